//! The implicit methods of model-exchange instances, from the `diffsol` crate
//! (dense `nalgebra` matrices, LU): `bdf`, the variable-order BDF (NDF) of
//! `diffsol::Bdf`, for stiff models, and `esdirk`, the ESDIRK34 tableau of
//! `diffsol::Sdirk`. Both integrate the states scaled by their nominals (as
//! the explicit methods do), with the same rtol and atol, each call from its
//! initial point with the solver's own initial step and no history, and call
//! back after every accepted step ([`Rhs::accepted`]: event indicators,
//! `CompletedIntegratorStep`), so event handling and `locate` are those of
//! every method.
//!
//! The Newton iteration's Jacobian of the scaled right-hand side,
//! `diag(1/n)·J·diag(n)`, is built column by column from J·v: the FMU's
//! directional derivatives of the derivatives with respect to the states
//! where its `ModelExchange` element declares `providesDirectionalDerivative`
//! (FMI 3.0: `providesDirectionalDerivatives`) and every state is a scalar,
//! else forward differences of the derivatives.
//!
//! The largest step is kept by a stop time `max_step` ahead of each accepted
//! step (diffsol has no largest step of its own): the step that would pass
//! it is shortened to end there.

use std::cell::RefCell;

use diffsol::error::OdeSolverError;
use diffsol::{
    DiffsolError, NalgebraLU, NalgebraMat, NalgebraVec, OdeBuilder, OdeEquations, OdeSolverMethod,
    OdeSolverStopReason,
};

use super::{Method, Rhs, Settings};
use crate::error::{one_line, Error, Result};
use crate::model_description::{ModelDescription, ValueReference};

/// The most accepted steps in one call, as for the explicit methods.
const MAX_STEPS: usize = 100_000;

/// A base point of the differences: time, scaled states, scaled derivatives.
type Base = (f64, Vec<f64>, Vec<f64>);

/// Where J·v comes from.
enum Jacobian {
    /// The FMU's directional derivatives: the derivatives' and the states'
    /// value references, in the order of the state vector.
    Directional {
        unknowns: Vec<ValueReference>,
        knowns: Vec<ValueReference>,
        seed: RefCell<Vec<f64>>,
        sensitivity: RefCell<Vec<f64>>,
    },
    /// Forward differences, with the derivatives at the last base point
    /// (time, scaled states, scaled derivatives) kept: the Jacobian's columns
    /// share it.
    Differences {
        base: RefCell<Option<Base>>,
        y: RefCell<Vec<f64>>,
        dy: RefCell<Vec<f64>>,
    },
}

impl Jacobian {
    fn new(md: &ModelDescription, n: usize) -> Jacobian {
        match directional(md, n) {
            Some((unknowns, knowns)) => Jacobian::Directional {
                unknowns,
                knowns,
                seed: RefCell::new(vec![0.0; n]),
                sensitivity: RefCell::new(vec![0.0; n]),
            },
            None => Jacobian::Differences {
                base: RefCell::new(None),
                y: RefCell::new(vec![0.0; n]),
                dy: RefCell::new(vec![0.0; n]),
            },
        }
    }
}

/// The value references of the derivatives (unknowns) and of their states
/// (knowns), in the order of the state vector, where the FMU provides
/// directional derivatives for model exchange and the `n` states are scalars.
fn directional(
    md: &ModelDescription,
    n: usize,
) -> Option<(Vec<ValueReference>, Vec<ValueReference>)> {
    if !md.model_exchange.as_ref()?.provides_directional_derivative {
        return None;
    }
    let derivatives = &md.model_structure.derivatives;
    if derivatives.len() != n {
        return None;
    }
    let mut unknowns = Vec::with_capacity(n);
    let mut knowns = Vec::with_capacity(n);
    for d in derivatives {
        let derivative = md.variable_by_index(d.index)?;
        let state = md.variable_by_index(derivative.real()?.derivative?)?;
        if derivative.is_array() || state.is_array() {
            return None;
        }
        unknowns.push(derivative.value_reference);
        knowns.push(state.value_reference);
    }
    Some((unknowns, knowns))
}

impl Rhs<'_> {
    /// The scaled derivatives for the solver: zeros once a call failed (the
    /// failure is kept; the solver is stopped after its step).
    fn eval(&self, tau: f64, y: &[f64], dy: &mut [f64]) {
        if self.failure.borrow().is_some() {
            dy.fill(0.0);
            return;
        }
        if let Err(e) = self.derivatives(tau, y, dy) {
            self.fail(e);
            dy.fill(0.0);
        }
    }

    /// J·v of the scaled right-hand side at (tau, y), as [`Rhs::eval`].
    fn jacobian_times(&self, jacobian: &Jacobian, tau: f64, y: &[f64], v: &[f64], out: &mut [f64]) {
        if self.failure.borrow().is_some() {
            out.fill(0.0);
            return;
        }
        let result = match jacobian {
            Jacobian::Directional {
                unknowns,
                knowns,
                seed,
                sensitivity,
            } => self.directional_times(
                unknowns,
                knowns,
                &mut seed.borrow_mut(),
                &mut sensitivity.borrow_mut(),
                tau,
                y,
                v,
                out,
            ),
            Jacobian::Differences { base, y: yp, dy } => self.difference_times(
                &mut base.borrow_mut(),
                &mut yp.borrow_mut(),
                &mut dy.borrow_mut(),
                tau,
                y,
                v,
                out,
            ),
        };
        if let Err(e) = result {
            self.fail(e);
            out.fill(0.0);
        }
    }

    /// diag(1/n)·J·diag(n)·v with the FMU's directional derivative.
    #[allow(clippy::too_many_arguments)]
    fn directional_times(
        &self,
        unknowns: &[ValueReference],
        knowns: &[ValueReference],
        seed: &mut [f64],
        sensitivity: &mut [f64],
        tau: f64,
        y: &[f64],
        v: &[f64],
        out: &mut [f64],
    ) -> Result<()> {
        self.set(tau, y)?;
        for ((s, v), n) in seed.iter_mut().zip(v).zip(self.nominals) {
            *s = v * n;
        }
        let mut fmu = self.fmu.borrow_mut();
        fmu.get_directional_derivative(unknowns, knowns, seed, sensitivity)?;
        if let Some(i) = sensitivity.iter().position(|d| !d.is_finite()) {
            return Err(Error::ModelExchange {
                instance: fmu.name().to_owned(),
                time: self.t0 + tau,
                cause: format!(
                    "the directional derivative of the state derivatives is {} in row {} of {}",
                    sensitivity[i],
                    i + 1,
                    sensitivity.len()
                ),
            });
        }
        for ((o, s), n) in out.iter_mut().zip(sensitivity.iter()).zip(self.nominals) {
            *o = s / n;
        }
        Ok(())
    }

    /// J·v by a forward difference along v, of step √ε·max(1, |y_i| where
    /// v_i ≠ 0) / max|v_i|.
    #[allow(clippy::too_many_arguments)]
    fn difference_times(
        &self,
        base: &mut Option<Base>,
        yp: &mut [f64],
        dyp: &mut [f64],
        tau: f64,
        y: &[f64],
        v: &[f64],
        out: &mut [f64],
    ) -> Result<()> {
        let v_max = v.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if v_max == 0.0 {
            out.fill(0.0);
            return Ok(());
        }
        let same = |(t, yb, _): &Base| {
            t.to_bits() == tau.to_bits()
                && yb.iter().zip(y).all(|(a, b)| a.to_bits() == b.to_bits())
        };
        if !base.as_ref().is_some_and(same) {
            let mut dy = vec![0.0; y.len()];
            self.derivatives(tau, y, &mut dy)?;
            *base = Some((tau, y.to_vec(), dy));
        }
        let Some((_, _, dy)) = base.as_ref() else {
            return Ok(());
        };
        let scale = y
            .iter()
            .zip(v)
            .filter(|(_, v)| **v != 0.0)
            .fold(1.0f64, |m, (y, _)| m.max(y.abs()));
        let h = f64::EPSILON.sqrt() * scale / v_max;
        for ((p, y), v) in yp.iter_mut().zip(y).zip(v) {
            *p = y + h * v;
        }
        self.derivatives(tau, yp, dyp)?;
        for ((o, a), b) in out.iter_mut().zip(dyp.iter()).zip(dy) {
            *o = (a - b) / h;
        }
        Ok(())
    }

    /// After an accepted step: true to stop (an event, a request to
    /// terminate, or a failure, which is kept).
    fn accepted_step(&mut self, tau: f64, y: &[f64]) -> bool {
        if self.failure.borrow().is_some() {
            return true;
        }
        super::dopri5::Problem::accepted(self, tau, y)
    }
}

/// One integration of `rhs` from (tau0, y0) towards tau1 with `bdf` or
/// `esdirk`, stopped early by [`Rhs::check_accepted`]: the last point reached. A
/// failure, the FMU's or the solver's (one line naming the instance, the
/// time and the cause), is left in `rhs.failure`.
pub(super) fn solve(
    settings: &Settings,
    rhs: &mut Rhs<'_>,
    tau0: f64,
    tau1: f64,
    y0: &[f64],
) -> (f64, Vec<f64>) {
    // NaN spans included: nothing to integrate.
    if tau1.partial_cmp(&tau0) != Some(std::cmp::Ordering::Greater) || y0.is_empty() {
        return (tau0, y0.to_vec());
    }
    let n = y0.len();
    let jacobian = Jacobian::new(rhs.fmu.borrow().model_description(), n);
    let rhs = RefCell::new(rhs);
    let built = OdeBuilder::<NalgebraMat<f64>>::new()
        .t0(tau0)
        .rtol(settings.rtol)
        .atol([settings.atol])
        .rhs_implicit(
            |y: &[f64], _p: &[f64], tau: f64, dy: &mut [f64]| rhs.borrow().eval(tau, y, dy),
            |y: &[f64], _p: &[f64], tau: f64, v: &[f64], out: &mut [f64]| {
                rhs.borrow().jacobian_times(&jacobian, tau, y, v, out)
            },
        )
        .init(
            |_p: &[f64], _t: f64, y: &mut [f64]| y.copy_from_slice(y0),
            n,
        )
        .build();
    let result = built.map_err(|e| (None, e)).and_then(|mut problem| {
        problem.ode_options.max_number_timesteps = MAX_STEPS;
        match settings.method {
            Method::Esdirk => {
                let mut solver = problem
                    .esdirk34::<NalgebraLU<f64>>()
                    .map_err(|e| (None, e))?;
                drive(&mut solver, &rhs, tau1, settings.max_step)
            }
            _ => {
                let mut solver = problem.bdf::<NalgebraLU<f64>>().map_err(|e| (None, e))?;
                drive(&mut solver, &rhs, tau1, settings.max_step)
            }
        }
    });
    let rhs = rhs.into_inner();
    match result {
        Ok(end) => end,
        Err((tau, e)) => {
            let e = solver_error(rhs, settings, tau.unwrap_or(tau0), &e);
            rhs.fail(e);
            (tau.unwrap_or(tau0), y0.to_vec())
        }
    }
}

/// A solver's failure with the time it was at, where known.
type Failure = (Option<f64>, DiffsolError);

/// Steps `solver` to tau1 (stop times at most `max_step` apart), calling
/// back after every accepted step; stops where the callback says so or the
/// FMU failed.
fn drive<'a, Eqn, S>(
    solver: &mut S,
    rhs: &RefCell<&mut Rhs<'_>>,
    tau1: f64,
    max_step: f64,
) -> std::result::Result<(f64, Vec<f64>), Failure>
where
    Eqn: OdeEquations<T = f64, V = NalgebraVec<f64>> + 'a,
    S: OdeSolverMethod<'a, Eqn>,
{
    let failed = |solver: &S, e| (Some(solver.state().t), e);
    let mut y = Vec::new();
    let mut stop = next_stop(solver.state().t, tau1, max_step);
    solver.set_stop_time(stop).map_err(|e| failed(solver, e))?;
    loop {
        let reason = solver.step().map_err(|e| failed(solver, e))?;
        let state = solver.state();
        let tau = state.t;
        y.clear();
        y.extend_from_slice(state.y.batch_as_slice(0));
        if rhs.borrow_mut().accepted_step(tau, &y) {
            return Ok((tau, y));
        }
        if reason == OdeSolverStopReason::TstopReached {
            if stop == tau1 {
                return Ok((tau1, y));
            }
            stop = next_stop(tau, tau1, max_step);
            if let Err(e) = solver.set_stop_time(stop) {
                if stop == tau1 {
                    // Within the solver's resolution of time of the end.
                    return Ok((tau1, y));
                }
                // A largest step below the resolution of time: to the end.
                stop = tau1;
                solver.set_stop_time(stop).map_err(|_| failed(solver, e))?;
            }
        }
    }
}

/// The next stop time from tau: tau1, or `max_step` ahead if that is
/// sooner.
fn next_stop(tau: f64, tau1: f64, max_step: f64) -> f64 {
    if tau1 - tau <= max_step {
        tau1
    } else {
        (tau + max_step).min(tau1)
    }
}

/// The solver's failure as one line naming the instance and the time, as
/// the explicit methods' (`integration_error`).
fn solver_error(rhs: &Rhs<'_>, settings: &Settings, tau: f64, e: &DiffsolError) -> Error {
    let what = match e {
        DiffsolError::OdeSolverError(OdeSolverError::StepSizeTooSmall { .. }) => {
            "cannot reach the tolerance: the step size fell below the resolution of time"
                .to_string()
        }
        DiffsolError::OdeSolverError(OdeSolverError::TooManyTimesteps { num_steps, .. }) => {
            format!("needs more than {num_steps} steps")
        }
        DiffsolError::OdeSolverError(OdeSolverError::TooManyErrorTestFailures {
            num_failures,
            ..
        }) => format!("failed its error test {num_failures} times in one step"),
        DiffsolError::OdeSolverError(OdeSolverError::TooManyNonlinearSolverFailures {
            num_failures,
            ..
        }) => format!(
            "found no solution of its implicit equations ({num_failures} Newton iterations failed in one step)"
        ),
        DiffsolError::LaError(e) => format!(
            "cannot solve with its iteration matrix (singular Jacobian?): {}",
            one_line(&e.to_string())
        ),
        DiffsolError::NonLinearSolverError(e) => {
            format!("failed in its Newton iteration: {}", one_line(&e.to_string()))
        }
        other => format!("failed: {}", one_line(&other.to_string())),
    };
    super::integrator_stopped(rhs, settings, tau, &what)
}

#[cfg(test)]
mod tests {
    use super::directional;
    use crate::Fmu;

    fn open(path: &str) -> Option<Fmu> {
        tether_fmu_build::fixture_fmu(path).map(|p| Fmu::open(p).unwrap())
    }

    /// VanDerPol declares directional derivatives (FMI 2.0 and 3.0): the
    /// derivatives der(x0), der(x1) (value references 2, 4) of the states
    /// x0, x1 (1, 3); Dahlquist does not; a state count other than the model
    /// structure's takes differences.
    #[test]
    fn directional_derivatives_where_the_fmu_declares_them() {
        for standard in ["fmi2", "fmi3"] {
            let Some(vdp) = open(&format!("reference-fmus/{standard}/VanDerPol.fmu")) else {
                return;
            };
            let md = vdp.model_description();
            assert_eq!(
                directional(md, 2),
                Some((vec![2, 4], vec![1, 3])),
                "{standard}"
            );
            assert_eq!(directional(md, 3), None, "{standard}");
            let Some(dahlquist) = open(&format!("reference-fmus/{standard}/Dahlquist.fmu")) else {
                return;
            };
            assert_eq!(directional(dahlquist.model_description(), 1), None);
        }
    }
}
