//! [`MeCalls`]: the model-exchange functions of an FMI 2.0 ([`LocalInstance`])
//! or FMI 3.0 ([`Fmi3Instance`]) instance made for model exchange, in one set of
//! words, so that [`MeInstance`](super::MeInstance) drives both alike.

use crate::component::fmi2::EventInfo;
use crate::error::Result;
use crate::instance::{Fmi3Instance, LocalInstance};
use crate::interface::FmuInstance;
use crate::model_description::ValueReference;

/// The model-exchange calls of one instance (its values and life cycle are
/// those of [`FmuInstance`]).
pub(crate) trait MeCalls: FmuInstance {
    /// The numbers of continuous states and event indicators, once initialized.
    fn sizes(&mut self) -> Result<(usize, usize)>;
    /// `SetTime` (also the time errors name).
    fn set_time(&mut self, t: f64) -> Result<()>;
    /// `SetContinuousStates`.
    fn set_continuous_states(&mut self, x: &[f64]) -> Result<()>;
    /// `GetDerivatives` / `GetContinuousStateDerivatives`.
    fn get_derivatives(&mut self, dx: &mut [f64]) -> Result<()>;
    /// `GetEventIndicators`.
    fn get_event_indicators(&mut self, z: &mut [f64]) -> Result<()>;
    /// `GetContinuousStates`.
    fn get_continuous_states(&mut self, x: &mut [f64]) -> Result<()>;
    /// `GetNominalsOfContinuousStates`.
    fn get_nominals(&mut self, nominals: &mut [f64]) -> Result<()>;
    /// `EnterEventMode`.
    fn enter_event_mode(&mut self) -> Result<()>;
    /// `NewDiscreteStates` / `UpdateDiscreteStates`.
    fn update_discrete_states(&mut self) -> Result<EventInfo>;
    /// `EnterContinuousTimeMode`.
    fn enter_continuous_time_mode(&mut self) -> Result<()>;
    /// `CompletedIntegratorStep` with `noSetFMUStatePriorToCurrentPoint`:
    /// (enter event mode, terminate simulation).
    fn completed_integrator_step(&mut self, no_set_prior: bool) -> Result<(bool, bool)>;
    /// `GetDirectionalDerivative` of scalar variables: `sensitivity =
    /// ∂unknowns/∂knowns · seed` (the FMU declares
    /// `providesDirectionalDerivative(s)`).
    fn get_directional_derivative(
        &mut self,
        unknowns: &[ValueReference],
        knowns: &[ValueReference],
        seed: &[f64],
        sensitivity: &mut [f64],
    ) -> Result<()>;
    /// The function names, for messages: (derivatives, new discrete states,
    /// completed integrator step).
    fn names(&self) -> (&'static str, &'static str, &'static str);
}

impl MeCalls for LocalInstance {
    fn sizes(&mut self) -> Result<(usize, usize)> {
        let me = self.model_description().model_exchange.as_ref();
        Ok(me.map_or((0, 0), |me| {
            (
                me.number_of_continuous_states,
                me.number_of_event_indicators,
            )
        }))
    }
    fn set_time(&mut self, t: f64) -> Result<()> {
        let raw = self.instance_mut().raw();
        raw.time = t;
        raw.fmi2SetTime(t)
    }
    fn set_continuous_states(&mut self, x: &[f64]) -> Result<()> {
        self.instance_mut().raw().fmi2SetContinuousStates(x)
    }
    fn get_derivatives(&mut self, dx: &mut [f64]) -> Result<()> {
        self.instance_mut().raw().fmi2GetDerivatives(dx)
    }
    fn get_event_indicators(&mut self, z: &mut [f64]) -> Result<()> {
        self.instance_mut().raw().fmi2GetEventIndicators(z)
    }
    fn get_continuous_states(&mut self, x: &mut [f64]) -> Result<()> {
        self.instance_mut().raw().fmi2GetContinuousStates(x)
    }
    fn get_nominals(&mut self, nominals: &mut [f64]) -> Result<()> {
        self.instance_mut()
            .raw()
            .fmi2GetNominalsOfContinuousStates(nominals)
    }
    fn enter_event_mode(&mut self) -> Result<()> {
        self.instance_mut().raw().fmi2EnterEventMode()
    }
    fn update_discrete_states(&mut self) -> Result<EventInfo> {
        self.instance_mut().raw().fmi2NewDiscreteStates()
    }
    fn enter_continuous_time_mode(&mut self) -> Result<()> {
        self.instance_mut().raw().fmi2EnterContinuousTimeMode()
    }
    fn completed_integrator_step(&mut self, no_set_prior: bool) -> Result<(bool, bool)> {
        self.instance_mut()
            .raw()
            .fmi2CompletedIntegratorStep(no_set_prior)
    }
    fn get_directional_derivative(
        &mut self,
        unknowns: &[ValueReference],
        knowns: &[ValueReference],
        seed: &[f64],
        sensitivity: &mut [f64],
    ) -> Result<()> {
        self.instance_mut()
            .raw()
            .fmi2GetDirectionalDerivative(unknowns, knowns, seed, sensitivity)
    }
    fn names(&self) -> (&'static str, &'static str, &'static str) {
        (
            "fmi2GetDerivatives",
            "fmi2NewDiscreteStates",
            "fmi2CompletedIntegratorStep",
        )
    }
}

impl MeCalls for Fmi3Instance {
    fn sizes(&mut self) -> Result<(usize, usize)> {
        let raw = self.raw_mut();
        Ok((
            raw.fmi3GetNumberOfContinuousStates()?,
            raw.fmi3GetNumberOfEventIndicators()?,
        ))
    }
    fn set_time(&mut self, t: f64) -> Result<()> {
        let raw = self.raw_mut();
        raw.time = t;
        raw.fmi3SetTime(t)
    }
    fn set_continuous_states(&mut self, x: &[f64]) -> Result<()> {
        self.raw_mut().fmi3SetContinuousStates(x)
    }
    fn get_derivatives(&mut self, dx: &mut [f64]) -> Result<()> {
        self.raw_mut().fmi3GetContinuousStateDerivatives(dx)
    }
    fn get_event_indicators(&mut self, z: &mut [f64]) -> Result<()> {
        self.raw_mut().fmi3GetEventIndicators(z)
    }
    fn get_continuous_states(&mut self, x: &mut [f64]) -> Result<()> {
        self.raw_mut().fmi3GetContinuousStates(x)
    }
    fn get_nominals(&mut self, nominals: &mut [f64]) -> Result<()> {
        self.raw_mut().fmi3GetNominalsOfContinuousStates(nominals)
    }
    fn enter_event_mode(&mut self) -> Result<()> {
        self.raw_mut().fmi3EnterEventMode()
    }
    fn update_discrete_states(&mut self) -> Result<EventInfo> {
        self.raw_mut().fmi3UpdateDiscreteStates()
    }
    fn enter_continuous_time_mode(&mut self) -> Result<()> {
        self.raw_mut().fmi3EnterContinuousTimeMode()
    }
    fn completed_integrator_step(&mut self, no_set_prior: bool) -> Result<(bool, bool)> {
        self.raw_mut().fmi3CompletedIntegratorStep(no_set_prior)
    }
    fn get_directional_derivative(
        &mut self,
        unknowns: &[ValueReference],
        knowns: &[ValueReference],
        seed: &[f64],
        sensitivity: &mut [f64],
    ) -> Result<()> {
        self.raw_mut()
            .fmi3GetDirectionalDerivative(unknowns, knowns, seed, sensitivity)
    }
    fn names(&self) -> (&'static str, &'static str, &'static str) {
        (
            "fmi3GetContinuousStateDerivatives",
            "fmi3UpdateDiscreteStates",
            "fmi3CompletedIntegratorStep",
        )
    }
}
