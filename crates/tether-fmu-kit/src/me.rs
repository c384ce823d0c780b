//! Model exchange: the importer owns time and continuous states, sets them with
//! `fmi2SetTime` / `fmi2SetContinuousStates` (or the fmi3 functions) and integrates
//! the derivatives the instance evaluates from (t, x, u) with the model's
//! [`derivatives`](crate::Model::derivatives). Outputs are read as in
//! co-simulation (`fmi2GetReal` evaluates [`outputs`](crate::Model::outputs) at the
//! instance's t, x and inputs). The kit's models have no events: no event
//! indicators, no time events, and event mode changes nothing.

use crate::instance::{Failure, Instance, Outcome};
use crate::model::Model;

impl<M: Model> Instance<M> {
    /// Refuses a model-exchange call on a co-simulation instance.
    fn model_exchange(&self) -> Outcome {
        if self.me {
            Ok(())
        } else {
            Err(Failure::usage(
                "not a model-exchange instance (instantiated for co-simulation)",
            ))
        }
    }

    fn states_count(&self, n: usize) -> Outcome {
        let expected = M::DECLARATION.states.len();
        if n == expected {
            Ok(())
        } else {
            Err(Failure::usage(format!(
                "{n} continuous states given, the model has {expected}"
            )))
        }
    }

    /// fmi2SetTime.
    pub fn set_time(&mut self, t: f64) -> Outcome {
        self.model_exchange()?;
        if !t.is_finite() {
            return Err(Failure::usage(format!("invalid time {t}")));
        }
        self.data.time = t;
        Ok(())
    }

    /// fmi2SetContinuousStates.
    pub fn set_continuous_states(&mut self, x: &[f64]) -> Outcome {
        self.model_exchange()?;
        self.states_count(x.len())?;
        self.data.states.copy_from_slice(x);
        Ok(())
    }

    /// fmi2GetContinuousStates (the initial states until the importer sets them).
    pub fn get_continuous_states(&mut self, x: &mut [f64]) -> Outcome {
        self.model_exchange()?;
        self.states_count(x.len())?;
        self.ensure_model()?;
        x.copy_from_slice(&self.data.states);
        Ok(())
    }

    /// fmi2GetDerivatives: ẋ = f(t, x, u) at the instance's time, states and inputs.
    pub fn get_derivatives(&mut self, dx: &mut [f64]) -> Outcome {
        self.model_exchange()?;
        self.states_count(dx.len())?;
        self.with_model(|model, d, u| model.derivatives(d.time, &d.states, u, dx))
    }

    /// fmi2GetNominalsOfContinuousStates: 1 for every state.
    pub fn get_nominals(&mut self, nominals: &mut [f64]) -> Outcome {
        self.model_exchange()?;
        self.states_count(nominals.len())?;
        nominals.fill(1.0);
        Ok(())
    }

    /// fmi2GetEventIndicators: the kit's models have none.
    pub fn get_event_indicators(&mut self, n: usize) -> Outcome {
        self.model_exchange()?;
        if n == 0 {
            Ok(())
        } else {
            Err(Failure::usage(format!(
                "{n} event indicators asked for, the model has none"
            )))
        }
    }

    /// fmi2EnterEventMode, fmi2EnterContinuousTimeMode: nothing changes (no events).
    pub fn change_mode(&mut self) -> Outcome {
        self.model_exchange()
    }

    /// fmi2NewDiscreteStates / fmi3UpdateDiscreteStates: no discrete states, no
    /// time events; returns whether the model asks to end the simulation.
    pub fn new_discrete_states(&mut self) -> Outcome<bool> {
        self.model_exchange()?;
        self.terminate_requested()
    }

    /// fmi2CompletedIntegratorStep: no event mode is ever needed; returns whether
    /// the model asks to end the simulation ([`Model::terminate`]) at the
    /// instance's time and states.
    pub fn completed_integrator_step(&mut self) -> Outcome<bool> {
        self.model_exchange()?;
        self.terminate_requested()
    }

    fn terminate_requested(&mut self) -> Outcome<bool> {
        let end = self.with_model(|model, d, _| model.terminate(d.time, &d.states))?;
        self.terminated |= end;
        Ok(end)
    }
}
