//! Value access of an [`Instance`]: get/set by value reference, input derivatives and
//! output derivatives. Every request is checked completely before anything is changed,
//! so a refused call has no effect.

use crate::declaration::{Slot, VarType};
use crate::input::{eval_all, InputJet};
use crate::instance::{Failure, Instance, Outcome};
use crate::integrate;
use crate::machine::MachineState;
use crate::model::Model;

impl<M: Model> Instance<M> {
    /// The variable behind `vr`, which must be of type `ty`.
    #[inline]
    fn slot(&self, vr: u32, ty: VarType) -> Outcome<Slot> {
        match self.slots.get(vr as usize) {
            Some(&slot) if slot.var_type() == ty => Ok(slot),
            found => Err(Self::wrong_slot(vr, found.copied(), ty)),
        }
    }

    #[cold]
    #[inline(never)]
    fn wrong_slot(vr: u32, found: Option<Slot>, ty: VarType) -> Failure {
        match found {
            None => Failure::usage(format!("unknown value reference {vr}")),
            Some(slot) => Failure::usage(format!(
                "value reference {vr} ({}) is a {} variable, not {}",
                M::DECLARATION.name(slot),
                slot.var_type().name(),
                ty.name()
            )),
        }
    }

    /// Outputs and state derivatives are evaluated only when asked for, once per
    /// call. The value references are checked before anything is evaluated.
    #[inline(always)]
    pub fn get_real(&mut self, vrs: &[u32], values: &mut [f64]) -> Outcome {
        let (mut wants_y, mut wants_dx, mut wants_model) = (false, false, false);
        for &vr in vrs {
            match self.slot(vr, VarType::Real)? {
                Slot::Output(_) => wants_y = true,
                Slot::Derivative(_) => wants_dx = true,
                Slot::State(_) => wants_model = true,
                _ => {}
            }
        }
        if wants_y || wants_dx || wants_model {
            self.ensure_model()?;
            let Instance {
                model: Some(model),
                data: d,
                scratch,
                ..
            } = self
            else {
                return Err(Failure::usage("model not built"));
            };
            if wants_y || wants_dx {
                scratch.u.resize(d.inputs.len(), 0.0);
                eval_all(&d.inputs, 0.0, &mut scratch.u);
            }
            if wants_y {
                scratch.y.resize(M::DECLARATION.outputs.len(), 0.0);
                model.outputs(d.time, &d.states, &scratch.u, &mut scratch.y);
            }
            if wants_dx {
                scratch.dx.resize(d.states.len(), 0.0);
                model.derivatives(d.time, &d.states, &scratch.u, &mut scratch.dx);
            }
        }
        let d = &self.data;
        for (value, &vr) in values.iter_mut().zip(vrs) {
            *value = match self.slots[vr as usize] {
                Slot::RealParameter(i) => d.reals[i],
                Slot::Input(i) => d.inputs[i].value,
                Slot::Output(i) => self.scratch.y[i],
                Slot::State(i) => d.states[i],
                Slot::Derivative(i) => self.scratch.dx[i],
                Slot::Time => d.time,
                Slot::IntegerParameter(_) | Slot::BooleanParameter(_) => 0.0,
            };
        }
        Ok(())
    }

    /// Parameters are `fixed`: settable until fmi2ExitInitializationMode.
    fn check_parameter_settable(&self, slot: Slot) -> Outcome {
        if matches!(
            self.data.machine,
            MachineState::Instantiated | MachineState::InitializationMode
        ) {
            Ok(())
        } else {
            let name = M::DECLARATION.name(slot);
            Err(Failure::usage(format!(
                "parameter {name} is fixed: it can only be set before fmi2ExitInitializationMode"
            )))
        }
    }

    fn check_real(&self, vr: u32, value: f64) -> Outcome<Slot> {
        let slot = self.slot(vr, VarType::Real)?;
        let name = || M::DECLARATION.name(slot);
        let declared = match slot {
            Slot::RealParameter(i) => {
                self.check_parameter_settable(slot)?;
                M::DECLARATION.all_real_parameters()[i]
            }
            Slot::Input(i) => M::DECLARATION.inputs[i],
            _ => {
                return Err(Failure::usage(format!(
                    "{} (value reference {vr}) cannot be set",
                    name()
                )))
            }
        };
        let below = declared.min.is_some_and(|m| value < m);
        let above = declared.max.is_some_and(|m| value > m);
        if !value.is_finite() || below || above {
            return Err(Failure::usage(format!(
                "{} = {value} is outside [{}, {}]",
                name(),
                declared.min.unwrap_or(f64::NEG_INFINITY),
                declared.max.unwrap_or(f64::INFINITY)
            )));
        }
        Ok(slot)
    }

    /// Setting an input resets its derivatives to 0 (the new value is held constant
    /// until fmi2SetRealInputDerivatives says otherwise). Every value is checked
    /// before any is set.
    #[inline(always)]
    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Outcome {
        for (&vr, &value) in vrs.iter().zip(values) {
            self.check_real(vr, value)?;
        }
        if let Some(k) = self.intermediate {
            let set = &mut self.samples[k].1;
            // FMI 3.0 intermediate update mode: only inputs, taken as the values at
            // the intermediate time.
            for (&vr, &value) in vrs.iter().zip(values) {
                match self.slots[vr as usize] {
                    Slot::Input(i) => set[i] = Some(value),
                    _ => {
                        return Err(Failure::usage(format!(
                            "{} (value reference {vr}) cannot be set in intermediate update mode (only inputs can)",
                            M::DECLARATION.name(self.slots[vr as usize])
                        )))
                    }
                }
            }
            return Ok(());
        }
        for (&vr, &value) in vrs.iter().zip(values) {
            match self.slots[vr as usize] {
                Slot::RealParameter(i) => {
                    self.data.reals[i] = value;
                    self.model = None;
                }
                Slot::Input(i) => {
                    self.data.inputs[i] = InputJet::constant(integrate::settled(value))
                }
                _ => {}
            }
        }
        Ok(())
    }

    pub fn get_integer(&mut self, vrs: &[u32], values: &mut [i32]) -> Outcome {
        for (value, &vr) in values.iter_mut().zip(vrs) {
            if let Slot::IntegerParameter(i) = self.slot(vr, VarType::Integer)? {
                *value = self.data.integers[i];
            }
        }
        Ok(())
    }

    pub fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Outcome {
        for (&vr, &value) in vrs.iter().zip(values) {
            let slot = self.slot(vr, VarType::Integer)?;
            self.check_parameter_settable(slot)?;
            if let Slot::IntegerParameter(i) = slot {
                let p = M::DECLARATION.integer_parameters[i];
                if p.min.is_some_and(|m| value < m) || p.max.is_some_and(|m| value > m) {
                    return Err(Failure::usage(format!(
                        "{} = {value} is outside [min, max]",
                        p.name
                    )));
                }
            }
        }
        for (&vr, &value) in vrs.iter().zip(values) {
            if let Ok(Slot::IntegerParameter(i)) = self.slot(vr, VarType::Integer) {
                self.data.integers[i] = value;
            }
        }
        self.model = None;
        Ok(())
    }

    pub fn get_boolean(&mut self, vrs: &[u32], values: &mut [bool]) -> Outcome {
        for (value, &vr) in values.iter_mut().zip(vrs) {
            if let Slot::BooleanParameter(i) = self.slot(vr, VarType::Boolean)? {
                *value = self.data.booleans[i];
            }
        }
        Ok(())
    }

    pub fn set_boolean(&mut self, vrs: &[u32], values: &[bool]) -> Outcome {
        for &vr in vrs {
            let slot = self.slot(vr, VarType::Boolean)?;
            self.check_parameter_settable(slot)?;
        }
        for (&vr, &value) in vrs.iter().zip(values) {
            if let Ok(Slot::BooleanParameter(i)) = self.slot(vr, VarType::Boolean) {
                self.data.booleans[i] = value;
            }
        }
        self.model = None;
        Ok(())
    }

    /// The model has no String variables: only empty requests succeed.
    pub fn strings(&mut self, vrs: &[u32]) -> Outcome {
        match vrs.first() {
            None => Ok(()),
            Some(vr) => Err(Failure::usage(format!(
                "value reference {vr} is not a String variable (the model has none)"
            ))),
        }
    }

    /// Orders 1 and 2 are held; the input is then the Taylor polynomial around the
    /// current communication point during the next fmi2DoStep.
    #[inline(always)]
    pub fn set_real_input_derivatives(
        &mut self,
        vrs: &[u32],
        orders: &[i32],
        values: &[f64],
    ) -> Outcome {
        for ((&vr, &order), &value) in vrs.iter().zip(orders).zip(values) {
            let slot = self.slot(vr, VarType::Real)?;
            if !matches!(slot, Slot::Input(_)) {
                return Err(Failure::usage(format!(
                    "{} is not an input",
                    M::DECLARATION.name(slot)
                )));
            }
            if !(1..=2).contains(&order) || !value.is_finite() {
                return Err(Failure::usage(format!("input derivative of order {order} = {value} is not supported (orders 1 and 2, finite values)")));
            }
        }
        for ((&vr, &order), &value) in vrs.iter().zip(orders).zip(values) {
            if let Slot::Input(i) = self.slots[vr as usize] {
                let jet = &mut self.data.inputs[i];
                if order == 1 {
                    jet.d1 = integrate::settled(value)
                } else {
                    jet.d2 = integrate::settled(value)
                }
            }
        }
        Ok(())
    }

    pub fn get_real_output_derivatives(
        &mut self,
        vrs: &[u32],
        orders: &[i32],
        values: &mut [f64],
    ) -> Outcome {
        let max = M::DECLARATION.max_output_derivative_order;
        let mut requests = Vec::with_capacity(vrs.len());
        for (&vr, &order) in vrs.iter().zip(orders) {
            let slot = self.slot(vr, VarType::Real)?;
            let Slot::Output(i) = slot else {
                return Err(Failure::usage(format!(
                    "{} is not an output",
                    M::DECLARATION.name(slot)
                )));
            };
            let order = u32::try_from(order).ok().filter(|o| (1..=max).contains(o));
            let order = order.ok_or_else(|| {
                Failure::usage(format!(
                    "derivative order must be in 1..={max} (maxOutputDerivativeOrder)"
                ))
            })?;
            requests.push((i, order));
        }
        let n = M::DECLARATION.outputs.len();
        let derivatives = self.with_model(|model, d, _| {
            (1..=max)
                .map(|order| {
                    let mut dy = vec![0.0; n];
                    model
                        .output_derivatives(d.time, &d.states, &d.inputs, order, &mut dy)
                        .then_some(dy)
                })
                .collect::<Vec<_>>()
        })?;
        for (value, (i, order)) in values.iter_mut().zip(requests) {
            let dy = derivatives[order as usize - 1].as_ref();
            *value = dy.ok_or_else(|| {
                Failure::usage(format!(
                    "the model provides no output derivatives of order {order}"
                ))
            })?[i];
        }
        Ok(())
    }
}
