//! Between macro steps: read a recorded value by name, and set an input or
//! a tunable parameter of an instance (what FMI 2.0 allows in step mode).

use tether_fmi::BaseType;

use super::Simulation;
use crate::spec::names::find_instance;
use crate::spec::StartValue;
use crate::start::set_between_steps;
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
        let coupled: Vec<u32> = slave.inputs.iter().map(|i| i.vr).collect();
        let kind = set_between_steps(
            slave.backend.as_mut(),
            slave.fmu.model_description(),
            variable,
            value,
            &coupled,
        )?;
        if kind == BaseType::Real {
            slave.counters.set_reals += 1;
        }
        Ok(())
    }
}
