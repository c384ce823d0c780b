//! Between macro steps: read a recorded value by name, and set an input or
//! a tunable parameter of an instance (what FMI 2.0 allows in step mode).

use tether_fmi::{BaseType, Inputs};

use super::Simulation;
use crate::slave::Run;
use crate::spec::names::find_instance;
use crate::spec::StartValue;
use crate::start::set_between_steps;
use crate::system::feedthrough::Feedthrough;
use crate::MasterError;

impl Simulation {
    /// The value of column `name` (see [`Simulation::columns`]) at the
    /// current point, or `None` if there is no such column.
    pub fn value(&self, name: &str) -> Option<f64> {
        self.columns()
            .iter()
            .position(|c| c == name)
            .map(|i| self.values()[i])
    }

    /// Set `target = value` (`instance.variable`) before the next macro
    /// step: an input the coupling does not drive, or a parameter with
    /// variability "tunable". Fixed parameters (FMI 2.0 allows them only
    /// before initialization; give them as start values), outputs and the
    /// inputs the coupling drives are refused with a message naming the
    /// variable, as are values of the wrong type or outside min/max.
    ///
    /// The value holds from the current point T_N on: the next step's
    /// predictor, perturbed runs and corrector all see it (the FMU state the
    /// method rolls back to is saved after it). The recorded values of the
    /// current point ([`Simulation::values`]) are those of the accepted step;
    /// outputs that depend on the variable show it from the next point on.
    pub fn set_parameter(&mut self, target: &str, value: &StartValue) -> Result<(), MasterError> {
        let malformed = || MasterError::StartValue {
            instance: String::new(),
            variable: target.to_string(),
            value: value.to_string(),
            reason: "expected INSTANCE.VARIABLE".into(),
        };
        let (instance, variable) = target
            .split_once('.')
            .filter(|(i, v)| !i.is_empty() && !v.is_empty())
            .ok_or_else(malformed)?;
        let names = self.system.slaves.iter().map(|s| s.name.as_str());
        let s = find_instance(&format!("set_parameter('{target}')"), instance, names)?;
        let slave = &mut self.system.slaves[s];
        let coupled: Vec<u32> = slave.coupled.inputs.iter().map(|i| i.vr).collect();
        let kind = set_between_steps(
            slave.backend.as_mut(),
            slave.fmu.model_description(),
            &mut slave.arrays,
            variable,
            value,
            &coupled,
        )?;
        match kind {
            BaseType::Real => slave.counters.set_reals += 1,
            BaseType::Integer | BaseType::Enumeration => slave.counters.set_integers += 1,
            BaseType::Boolean => slave.counters.set_booleans += 1,
            BaseType::String => slave.counters.set_strings += 1,
        }
        Ok(())
    }

    /// [`set_parameter`](Self::set_parameter) of a Real input with its time
    /// derivatives at the current point (`derivatives[k]` of order k + 1):
    /// an instance that declares `canInterpolateInputs` takes them through
    /// `fmi2SetRealInputDerivatives` and sees the polynomial over the next
    /// step; another one holds the value.
    pub fn set_input(
        &mut self,
        target: &str,
        value: f64,
        derivatives: &[f64],
    ) -> Result<(), MasterError> {
        self.set_parameter(target, &StartValue::Real(value))?;
        let (instance, variable) = target.split_once('.').unwrap_or_default();
        let Some(slave) = self.system.slaves.iter_mut().find(|s| s.name == instance) else {
            return Ok(());
        };
        if derivatives.is_empty() || !slave.caps.polynomial_inputs {
            return Ok(());
        }
        let Ok(var) = slave.fmu.model_description().variable(variable) else {
            return Ok(());
        };
        let vr = var.value_reference;
        let orders: Vec<i32> = (1..=derivatives.len() as i32).collect();
        slave.backend.set_inputs(&Inputs {
            vrs: &[vr],
            values: &[value],
            derivative_vrs: &vec![vr; derivatives.len()],
            orders: &orders,
            derivatives,
        })?;
        slave.counters.set_input_derivatives += 1;
        Ok(())
    }

    /// The values of the current point (as [`values`](Self::values)) with
    /// the multipliers solved again for the inputs as they are set now: the
    /// consistent multipliers (g̈ = 0, or the explicit method's condition)
    /// at the current time (at the start time, those the system file asks to
    /// be consistent), the signal connections settled around them, the
    /// outputs read back. No step is taken and the point the next step starts
    /// from is kept: the master's own state is restored afterwards and the
    /// instances only had their coupled inputs set, which every step sets
    /// again. For an exported FMU whose outputs depend directly on its
    /// inputs (docs/fmu-export.md).
    pub fn consistent_values(&mut self) -> Result<Vec<f64>, MasterError> {
        let saved = self.save_master();
        let time = self.time();
        let mut stats = crate::stats::RunStats::default();
        let solved = (|| {
            let system = &mut self.system;
            self.signals.initialize(&mut system.slaves)?;
            let mut feedthrough = Feedthrough::new(system);
            if self.grid.n() == 0 {
                // At the start, as the run began: the multipliers the system
                // file gives stay, "consistent" ones are solved.
                feedthrough.initial(system, self.level, time, &mut stats)?;
            } else {
                feedthrough.solve_all(system, self.level, time, &mut stats)?;
            }
            self.signals.initialize(&mut system.slaves)?;
            system.read_accepted(Run::Feedthrough)?;
            self.row.fill(system);
            Ok(self.row.values().to_vec())
        })();
        self.restore_master(&saved);
        solved
    }
}
