//! The coupled inputs and outputs of an instance: the inputs set from the
//! unknowns' polynomials, the outputs read after each run (checked to be
//! finite and within their divergence limits), and their buffers.

use tether_fmi::{BaseType, Causality, Inputs};

use super::{Run, Slave};
use crate::polynomial::Taylor;
use crate::MasterError;

/// A coupled input: `value = Σ coefficient · u[unknown]`; an element of an
/// FMI 3.0 array input is `element` of its `count` values (the others keep
/// their start values: an array is set whole).
#[derive(Debug, Clone)]
pub(crate) struct CoupledInput {
    pub vr: u32,
    pub element: usize,
    pub count: usize,
    pub terms: Vec<(usize, f64)>,
}

/// An output value read after each run: the variable itself or one of its
/// derivatives (order 1 or 2) through `fmi2GetRealOutputDerivatives`; an
/// element of an FMI 3.0 array output is `element` of its `count` values (the
/// array is read once per run).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct CoupledOutput {
    pub vr: u32,
    pub order: u32,
    pub element: usize,
    pub count: usize,
}

impl CoupledOutput {
    /// A scalar output (or its derivative).
    pub(crate) fn scalar(vr: u32, order: u32) -> CoupledOutput {
        CoupledOutput {
            vr,
            order,
            element: 0,
            count: 1,
        }
    }
}

/// The slot of a value read that no coupled output uses (an element of an
/// array nobody couples).
pub(super) const UNUSED: usize = usize::MAX;

/// The coupled inputs and outputs of an instance, and how they are set and
/// read (sized once by [`Slave::finalize`]: no allocation afterwards).
#[derive(Debug, Default)]
pub(crate) struct Coupled {
    pub inputs: Vec<CoupledInput>,
    /// The coupled inputs' values and derivatives as the instance takes them.
    pub input: InputBuffers,
    /// The place of each coupled input's value among the values set (the
    /// elements of an array input are set together).
    pub input_positions: Vec<usize>,
    /// The degree k of the unknowns' polynomials (`finalize`).
    pub order: usize,
    pub outputs: Vec<CoupledOutput>,
    pub value_vrs: Vec<u32>,
    /// The number of values `value_vrs` reads, when arrays make it differ
    /// from their number.
    pub value_count: Option<usize>,
    /// `value_vrs`, then the recorded outputs: the read at an accepted point,
    /// one call when no output derivative is read (`finalize`).
    pub accepted_vrs: Vec<u32>,
    /// The number of values `accepted_vrs` reads, as `value_count`.
    pub accepted_count: Option<usize>,
    /// The output derivatives read, `(variable, order)`.
    pub derivative_reads: Vec<(u32, i32)>,
    /// The slot in the coupled outputs of each value of `value_buf`.
    pub slots: Vec<usize>,
    /// A run's outputs as the instance returns them: the values
    /// (`value_vrs`), then the derivatives (`derivative_reads`).
    pub value_buf: Vec<f64>,
    /// Per coupled value (as `value_buf`), the magnitude beyond which it has
    /// diverged (crate::culprit); empty until set after initialization.
    pub limits: Vec<f64>,
    /// The first coupled value read beyond its limit in the latest step.
    pub beyond: Option<crate::culprit::Beyond>,
    /// The instance's own communication step as a multiple n of H (1: H,
    /// set at instantiation): with n > 1 the signals step it every n-th
    /// macro step.
    pub decimation: u64,
}

/// The coupled inputs' values and their derivatives (the first derivatives
/// of every input, then the second, as far as min(k, 2) asks).
#[derive(Debug, Default, Clone)]
pub(crate) struct InputBuffers {
    pub vrs: Vec<u32>,
    pub values: Vec<f64>,
    pub derivative_vrs: Vec<u32>,
    pub orders: Vec<i32>,
    pub derivatives: Vec<f64>,
}

impl InputBuffers {
    /// The inputs as last combined.
    pub(super) fn as_inputs(&self) -> Inputs<'_> {
        Inputs {
            vrs: &self.vrs,
            values: &self.values,
            derivative_vrs: &self.derivative_vrs,
            orders: &self.orders,
            derivatives: &self.derivatives,
        }
    }
}

/// The inputs' values (`values`) and derivatives (`derivatives`: the first
/// derivatives of every input, then the second, as far as min(k, 2) asks) as
/// sums over their terms.
pub(super) fn combine_inputs(
    inputs: &[CoupledInput],
    positions: &[usize],
    polys: &[Taylor],
    values: &mut [f64],
    derivatives: &mut [f64],
) {
    let n = inputs.len();
    for (i, (input, &position)) in inputs.iter().zip(positions).enumerate() {
        let mut p = Taylor::default();
        for &(m, c) in &input.terms {
            p.value += c * polys[m].value;
            p.d1 += c * polys[m].d1;
            p.d2 += c * polys[m].d2;
        }
        values[position] = p.value;
        if let Some(d1) = derivatives.get_mut(i) {
            *d1 = p.d1;
        }
        if let Some(d2) = derivatives.get_mut(n + i) {
            *d2 = p.d2;
        }
    }
}

impl Slave {
    /// Register a coupled Real input (an array's `element`, if any) driven by
    /// unknowns.
    pub(crate) fn add_input(
        &mut self,
        vr: u32,
        element: Option<crate::spec::names::Element>,
        unknown: usize,
        coefficient: f64,
    ) {
        let (element, count) = element.map_or((0, 1), |e| (e.index, e.count));
        if let Some(i) = self
            .coupled
            .inputs
            .iter_mut()
            .find(|i| i.vr == vr && i.element == element)
        {
            i.terms.push((unknown, coefficient));
        } else {
            self.coupled.inputs.push(CoupledInput {
                vr,
                element,
                count,
                terms: vec![(unknown, coefficient)],
            });
        }
    }

    /// Register a coupled output; returns its slot in `coupled_values`.
    pub(crate) fn add_output(&mut self, output: CoupledOutput) -> usize {
        if let Some(i) = self.coupled.outputs.iter().position(|o| *o == output) {
            return i;
        }
        self.coupled.outputs.push(output);
        self.coupled.outputs.len() - 1
    }

    /// The name of coupled output `slot`: the variable, or `der(x, order)`.
    pub(crate) fn coupled_name(&self, slot: usize) -> String {
        let output = self.coupled.outputs[slot];
        let md = self.fmu.model_description();
        let var = md
            .model_variables
            .iter()
            .filter(|v| v.value_reference == output.vr && v.base_type() == BaseType::Real)
            .max_by_key(|v| v.causality == Causality::Output);
        let name = match var {
            None => format!("#{}", output.vr),
            Some(v) if v.is_array() => self
                .arrays
                .element_names(md, v)
                .ok()
                .and_then(|names| names.into_iter().nth(output.element))
                .unwrap_or_else(|| v.name.clone()),
            Some(v) => v.name.clone(),
        };
        match output.order {
            0 => name,
            order => format!("der({name}, {order})"),
        }
    }

    /// The coupled outputs as read (`values`: the values of `value_vrs`,
    /// then the output derivatives) into their slots of `out`, counted, and
    /// checked to be finite and within their divergence limits.
    #[inline(always)]
    pub(super) fn take_coupled(
        &mut self,
        values: &[f64],
        out: &mut [f64],
        run: Run,
    ) -> Result<(), MasterError> {
        self.counters.get_output_derivatives += self.coupled.derivative_reads.len() as u64;
        // Every slot of `out` is written: when every value is finite, `out` is.
        let mut finite = true;
        for (&value, &slot) in values.iter().zip(&self.coupled.slots) {
            if slot == UNUSED {
                continue;
            }
            out[slot] = value;
            finite &= value.is_finite();
        }
        if !finite {
            return Err(self.first_non_finite(out, run));
        }
        let beyond = |(v, limit): (&f64, &f64)| v.abs() > *limit;
        if let Some(k) = values.iter().zip(&self.coupled.limits).position(beyond) {
            self.note_beyond(k, values[k], run);
        }
        Ok(())
    }

    /// The error naming the first coupled output in `out` that is not finite.
    #[cold]
    #[inline(never)]
    pub(super) fn first_non_finite(&self, out: &[f64], run: Run) -> MasterError {
        let slot = out
            .iter()
            .position(|v| !v.is_finite())
            .expect("a value read is not finite");
        self.non_finite(self.coupled_name(slot), out[slot], run)
    }

    /// Divergence limits `factor`·max(|v|, 1) around the coupled outputs
    /// `out` of the last read (the initial point's), for crate::culprit; the
    /// output derivatives are not limited.
    pub(crate) fn set_divergence_limits(&mut self, factor: f64, out: &[f64]) {
        let nv = self.values_len();
        self.coupled.limits = self.coupled.slots[..nv]
            .iter()
            .map(|&slot| match slot {
                UNUSED => f64::INFINITY,
                _ => (factor * out[slot].abs().max(1.0)).min(f64::MAX),
            })
            .collect();
    }

    /// The number of values the coupled outputs' read returns.
    pub(super) fn values_len(&self) -> usize {
        self.coupled
            .value_count
            .unwrap_or(self.coupled.value_vrs.len())
    }

    /// Coupled value `k` of the last read is beyond its limit: noted, unless
    /// a value of this step (a read at the same time or later) already is.
    #[cold]
    #[inline(never)]
    pub(super) fn note_beyond(&mut self, k: usize, value: f64, run: Run) {
        let time = self.backend.time();
        if self.coupled.beyond.as_ref().is_some_and(|b| b.time >= time) {
            return;
        }
        self.coupled.beyond = Some(crate::culprit::Beyond::new(
            self.coupled_name(self.coupled.slots[k]),
            value,
            self.coupled.limits[k],
            run.describe(),
            time,
        ));
    }

    /// The error for output `variable` = `value` (not finite) read after `run`.
    #[cold]
    #[inline(never)]
    pub(crate) fn non_finite(&self, variable: String, value: f64, run: Run) -> MasterError {
        MasterError::NonFiniteOutput {
            instance: self.name.clone(),
            variable,
            value,
            call: run.describe(),
            time: self.backend.time(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_with_several_terms_are_sums() {
        // Two inputs: u0 − 2·u1, and 0.5·u1; first and second derivatives (k = 2).
        let polys = [
            Taylor {
                value: 1.0,
                d1: 2.0,
                d2: 3.0,
            },
            Taylor {
                value: 10.0,
                d1: 20.0,
                d2: 30.0,
            },
        ];
        let inputs = [
            CoupledInput {
                vr: 0,
                element: 0,
                count: 1,
                terms: vec![(0, 1.0), (1, -2.0)],
            },
            CoupledInput {
                vr: 1,
                element: 0,
                count: 1,
                terms: vec![(1, 0.5)],
            },
        ];
        let (mut values, mut derivatives) = ([0.0; 2], [0.0; 4]);
        combine_inputs(&inputs, &[0, 1], &polys, &mut values, &mut derivatives);
        assert_eq!(values, [-19.0, 5.0]);
        assert_eq!(derivatives, [-38.0, 10.0, -57.0, 15.0]);
    }
}
