//! One communication step of the continuous states: the model's exact step if it has
//! one, else Dop853 (ode_solvers) with rtol = atol = `tolerance`.
//!
//! The system is integrated in autonomous form: the elapsed time τ = t − t_c is an
//! extra state with τ' = 1, and the model sees t = t_c + τ. ode_solvers 0.6.2
//! evaluates Dop853's 12th stage at the wrong time (its c₁₂ is 0 instead of 1), which
//! makes non-autonomous right-hand sides, such as any model with an interpolated
//! input, inaccurate (∫₀¹ 2t dt comes out as 0.99968 at rtol 1e-6) and slow. The
//! stage coefficients a_ij are right, so the autonomous form is exact again.

use std::cell::RefCell;

use ode_solvers::{DVector, Dop853, OutputType, System};

use crate::input::{eval_all, InputJet};
use crate::model::Model;

struct Rhs<'a, M> {
    model: &'a M,
    t_c: f64,
    inputs: &'a [InputJet],
    u: RefCell<Vec<f64>>,
}

impl<M: Model> System<f64, DVector<f64>> for Rhs<'_, M> {
    /// `y = [x…, τ]`.
    fn system(&self, _t: f64, y: &DVector<f64>, dy: &mut DVector<f64>) {
        let n = y.len() - 1;
        let tau = y[n];
        let mut u = self.u.borrow_mut();
        eval_all(self.inputs, tau, &mut u);
        self.model.derivatives(
            self.t_c + tau,
            &y.as_slice()[..n],
            &u,
            &mut dy.as_mut_slice()[..n],
        );
        dy[n] = 1.0;
    }
}

/// Advances `x` from `t_c` to `t_c + h` with the inputs as Taylor polynomials around
/// `t_c`; returns how (for the log) or why it failed.
#[inline]
pub fn step<M: Model>(
    model: &M,
    t_c: f64,
    h: f64,
    x: &mut [f64],
    inputs: &[InputJet],
    tolerance: f64,
) -> Result<&'static str, String> {
    if x.is_empty() {
        return Ok("no states");
    }
    if model.exact_step(t_c, h, x, inputs) {
        return check_finite(x, t_c + h).map(|()| "exact step");
    }
    dop853(model, t_c, h, x, inputs, tolerance)
}

/// [`step`] with Dop853: a separate, never inlined function, so that a model's
/// exact step does not carry the integrator's set-up in its path.
#[inline(never)]
fn dop853<M: Model>(
    model: &M,
    t_c: f64,
    h: f64,
    x: &mut [f64],
    inputs: &[InputJet],
    tolerance: f64,
) -> Result<&'static str, String> {
    let rhs = Rhs {
        model,
        t_c,
        inputs,
        u: RefCell::new(vec![0.0; inputs.len()]),
    };
    let y0 = DVector::from_iterator(x.len() + 1, x.iter().copied().chain([0.0]));
    let mut solver = match model.max_step().filter(|&max| max > 0.0 && max < h) {
        // Dop853's defaults (safety 0.9, β 0, step factors 1/3..6, automatic first
        // step, 100 000 steps, stiffness check every 1000), but at most `max` per step.
        Some(max) => Dop853::from_param(
            rhs,
            0.0,
            h,
            h,
            y0,
            tolerance,
            tolerance,
            0.9,
            0.0,
            0.333,
            6.0,
            max,
            0.0,
            100_000,
            1000,
            OutputType::Sparse,
        ),
        None => Dop853::new(rhs, 0.0, h, h, y0, tolerance, tolerance),
    };
    solver.set_output(OutputType::Sparse);
    solver
        .integrate()
        .map_err(|e| format!("Dop853 failed between t = {t_c} and t = {}: {e}", t_c + h))?;
    let end = solver.y_out().last().ok_or("Dop853 returned no solution")?;
    x.copy_from_slice(&end.as_slice()[..x.len()]);
    check_finite(x, t_c + h).map(|()| "Dop853")
}

#[inline]
fn check_finite(x: &[f64], t: f64) -> Result<(), String> {
    if x.iter().all(|v| v.is_finite()) {
        return Ok(());
    }
    not_finite(x, t)
}

#[cold]
#[inline(never)]
fn not_finite(x: &[f64], t: f64) -> Result<(), String> {
    match x.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(format!("state {i} is not finite ({}) at t = {t}", x[i])),
        None => Ok(()),
    }
}
