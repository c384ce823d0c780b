//! The inputs' polynomials over a step of a model-exchange instance: the
//! coupling polynomial of degree k of each input, u(t) = u(t₀) + Σ_j
//! u⁽ʲ⁾(t₀)·(t − t₀)ʲ/j! from the point t₀ it was set at, set at every time
//! the integrator evaluates the model, so the FMU sees the polynomial itself
//! (a co-simulation FMU gets only its derivatives at t₀).

use std::cell::RefCell;

use super::calls::MeCalls;
use crate::error::Result;
use crate::interface::Inputs;
use crate::model_description::ValueReference;

/// One input's polynomial.
#[derive(Debug, Default)]
struct Entry {
    vr: ValueReference,
    t0: f64,
    value: f64,
    /// The derivative of order j + 1 at `t0`.
    derivatives: Vec<f64>,
}

/// The inputs that follow a polynomial, each from the point it was set at, in
/// buffers reused between steps.
#[derive(Debug, Default)]
pub(crate) struct InputPolynomial {
    entries: Vec<Entry>,
    /// The value references and values set last.
    vrs: RefCell<Vec<ValueReference>>,
    u: RefCell<Vec<f64>>,
}

impl InputPolynomial {
    /// Takes `inputs` from `t0` on: each input given becomes the polynomial
    /// of its value and derivatives (or its value alone, held); the others
    /// keep theirs. The error names a derivative of an input without a
    /// value.
    pub(crate) fn take(&mut self, t0: f64, inputs: &Inputs<'_>) -> std::result::Result<(), u32> {
        for (&vr, &value) in inputs.vrs.iter().zip(inputs.values) {
            let i = match self.entries.iter().position(|e| e.vr == vr) {
                Some(i) => i,
                None => {
                    self.entries.push(Entry {
                        vr,
                        ..Entry::default()
                    });
                    self.entries.len() - 1
                }
            };
            let entry = &mut self.entries[i];
            entry.t0 = t0;
            entry.value = value;
            entry.derivatives.clear();
        }
        for ((vr, &order), &d) in inputs
            .derivative_vrs
            .iter()
            .zip(inputs.orders)
            .zip(inputs.derivatives)
        {
            let entry = self
                .entries
                .iter_mut()
                .find(|e| e.vr == *vr && inputs.vrs.contains(vr))
                .ok_or(*vr)?;
            let j = usize::try_from(order).unwrap_or(0).max(1);
            if entry.derivatives.len() < j {
                entry.derivatives.resize(j, 0.0);
            }
            entry.derivatives[j - 1] = d;
        }
        // Held inputs need nothing more: their values are set.
        self.entries.retain(|e| !e.derivatives.is_empty());
        Ok(())
    }

    /// The inputs in `vrs` are set to plain values: they follow no
    /// polynomial any more.
    pub(crate) fn forget(&mut self, vrs: &[ValueReference]) {
        if !self.entries.is_empty() {
            self.entries.retain(|e| !vrs.contains(&e.vr));
        }
    }

    /// Sets every input with a polynomial to its value at `t`.
    pub(crate) fn set(&self, fmu: &mut dyn MeCalls, t: f64) -> Result<()> {
        if self.entries.is_empty() {
            return Ok(());
        }
        let (mut vrs, mut u) = (self.vrs.borrow_mut(), self.u.borrow_mut());
        vrs.clear();
        u.clear();
        for e in &self.entries {
            let dt = t - e.t0;
            let (mut value, mut factor) = (e.value, 1.0);
            for (j, d) in e.derivatives.iter().enumerate() {
                factor *= dt / (j + 1) as f64;
                value += d * factor;
            }
            vrs.push(e.vr);
            u.push(value);
        }
        fmu.set_reals(&vrs, &u)
    }
}
