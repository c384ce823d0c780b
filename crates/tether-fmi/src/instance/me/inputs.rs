//! The inputs' polynomial over a step of a model-exchange instance: the
//! coupling polynomial of degree k, u(t) = u(t_N) + Σ_j u⁽ʲ⁾(t_N)·(t − t_N)ʲ/j!,
//! set at every time the integrator evaluates the model, so the FMU sees the
//! polynomial itself (a co-simulation FMU gets only its derivatives at t_N).

use std::cell::RefCell;

use super::calls::MeCalls;
use crate::error::Result;
use crate::interface::Inputs;
use crate::model_description::ValueReference;

/// The polynomial of the inputs set last, in buffers reused between steps.
#[derive(Debug, Default)]
pub(crate) struct InputPolynomial {
    /// Where the polynomial starts.
    t0: f64,
    vrs: Vec<ValueReference>,
    values: Vec<f64>,
    /// Each derivative: (index into `vrs`, order, value).
    terms: Vec<(usize, i32, f64)>,
    /// The values at the time set last.
    u: RefCell<Vec<f64>>,
}

impl InputPolynomial {
    /// Takes `inputs` from `t0` on: a polynomial when they carry derivatives,
    /// else none (their values stay as set). The error names a derivative of
    /// an input without a value.
    pub(crate) fn take(&mut self, t0: f64, inputs: &Inputs<'_>) -> std::result::Result<(), u32> {
        self.terms.clear();
        if inputs.derivative_vrs.is_empty() {
            self.vrs.clear();
            return Ok(());
        }
        self.t0 = t0;
        self.vrs.clear();
        self.vrs.extend_from_slice(inputs.vrs);
        self.values.clear();
        self.values.extend_from_slice(inputs.values);
        for ((vr, &order), &d) in inputs
            .derivative_vrs
            .iter()
            .zip(inputs.orders)
            .zip(inputs.derivatives)
        {
            let i = self.vrs.iter().position(|v| v == vr).ok_or(*vr)?;
            self.terms.push((i, order, d));
        }
        self.u.borrow_mut().resize(self.vrs.len(), 0.0);
        Ok(())
    }

    /// Sets the inputs to the polynomial at `t` (nothing without one).
    pub(crate) fn set(&self, fmu: &mut dyn MeCalls, t: f64) -> Result<()> {
        if self.terms.is_empty() {
            return Ok(());
        }
        let mut u = self.u.borrow_mut();
        u.copy_from_slice(&self.values);
        let dt = t - self.t0;
        for &(i, order, d) in &self.terms {
            let mut factor = 1.0;
            for j in 1..=order {
                factor *= dt / f64::from(j);
            }
            u[i] += d * factor;
        }
        fmu.set_reals(&self.vrs, &u)
    }
}
