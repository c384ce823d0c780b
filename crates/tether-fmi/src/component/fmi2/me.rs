//! The FMI 2.0 model-exchange functions of [`RawComponent`], one-to-one under their
//! C names, each through the fatal-state guard and the status check.

use super::RawComponent;
use crate::error::Result;
use crate::raw::*;

/// What `fmi2NewDiscreteStates` (and `fmi3UpdateDiscreteStates`) reports.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct EventInfo {
    pub new_discrete_states_needed: bool,
    pub terminate_simulation: bool,
    pub nominals_changed: bool,
    pub values_changed: bool,
    /// The next time event, if the FMU defines one.
    pub next_event_time: Option<f64>,
}

impl RawComponent {
    /// Runs a model-exchange function: refused (naming it) when the library
    /// lacks the model-exchange functions, else as every call.
    #[inline]
    fn call_me(
        &mut self,
        function: &'static str,
        call: impl FnOnce(&Fmi2MeFunctions, fmi2Component) -> fmi2Status,
    ) -> Result<()> {
        let library = std::sync::Arc::clone(&self.library);
        let me = library.me()?;
        self.call(function, |_, c| call(me, c))
    }

    /// `fmi2EnterEventMode`.
    pub(crate) fn fmi2EnterEventMode(&mut self) -> Result<()> {
        // SAFETY: the component is live.
        self.call_me("fmi2EnterEventMode", |f, c| unsafe {
            (f.fmi2EnterEventMode)(c)
        })
    }

    /// `fmi2NewDiscreteStates`.
    pub(crate) fn fmi2NewDiscreteStates(&mut self) -> Result<EventInfo> {
        let mut info = fmi2EventInfo::default();
        // SAFETY: `info` is a valid out-pointer for the call's duration.
        self.call_me("fmi2NewDiscreteStates", |f, c| unsafe {
            (f.fmi2NewDiscreteStates)(c, &mut info)
        })?;
        Ok(EventInfo {
            new_discrete_states_needed: info.newDiscreteStatesNeeded != fmi2False,
            terminate_simulation: info.terminateSimulation != fmi2False,
            nominals_changed: info.nominalsOfContinuousStatesChanged != fmi2False,
            values_changed: info.valuesOfContinuousStatesChanged != fmi2False,
            next_event_time: (info.nextEventTimeDefined != fmi2False).then_some(info.nextEventTime),
        })
    }

    /// `fmi2EnterContinuousTimeMode`.
    pub(crate) fn fmi2EnterContinuousTimeMode(&mut self) -> Result<()> {
        // SAFETY: the component is live.
        self.call_me("fmi2EnterContinuousTimeMode", |f, c| unsafe {
            (f.fmi2EnterContinuousTimeMode)(c)
        })
    }

    /// `fmi2CompletedIntegratorStep`: (enterEventMode, terminateSimulation).
    pub(crate) fn fmi2CompletedIntegratorStep(
        &mut self,
        no_set_fmu_state_prior: bool,
    ) -> Result<(bool, bool)> {
        let (mut event, mut terminate) = (fmi2False, fmi2False);
        // SAFETY: both out-pointers are valid for the call's duration.
        self.call_me("fmi2CompletedIntegratorStep", |f, c| unsafe {
            (f.fmi2CompletedIntegratorStep)(
                c,
                super::boolean(no_set_fmu_state_prior),
                &mut event,
                &mut terminate,
            )
        })?;
        Ok((event != fmi2False, terminate != fmi2False))
    }

    /// `fmi2SetTime`.
    pub(crate) fn fmi2SetTime(&mut self, time: f64) -> Result<()> {
        // SAFETY: scalar argument; the component is live.
        self.call_me("fmi2SetTime", |f, c| unsafe { (f.fmi2SetTime)(c, time) })
    }

    /// `fmi2SetContinuousStates` (`nx` = the length of `x`).
    pub(crate) fn fmi2SetContinuousStates(&mut self, x: &[f64]) -> Result<()> {
        // SAFETY: `x` holds `x.len()` values, passed as nx.
        self.call_me("fmi2SetContinuousStates", |f, c| unsafe {
            (f.fmi2SetContinuousStates)(c, x.as_ptr(), x.len())
        })
    }

    /// `fmi2GetDerivatives` into `out` (`nx` = its length).
    pub(crate) fn fmi2GetDerivatives(&mut self, out: &mut [f64]) -> Result<()> {
        // SAFETY: `out` is writable for `out.len()` values, passed as nx.
        self.call_me("fmi2GetDerivatives", |f, c| unsafe {
            (f.fmi2GetDerivatives)(c, out.as_mut_ptr(), out.len())
        })
    }

    /// `fmi2GetEventIndicators` into `out` (`ni` = its length).
    pub(crate) fn fmi2GetEventIndicators(&mut self, out: &mut [f64]) -> Result<()> {
        // SAFETY: `out` is writable for `out.len()` values, passed as ni.
        self.call_me("fmi2GetEventIndicators", |f, c| unsafe {
            (f.fmi2GetEventIndicators)(c, out.as_mut_ptr(), out.len())
        })
    }

    /// `fmi2GetContinuousStates` into `out` (`nx` = its length).
    pub(crate) fn fmi2GetContinuousStates(&mut self, out: &mut [f64]) -> Result<()> {
        // SAFETY: `out` is writable for `out.len()` values, passed as nx.
        self.call_me("fmi2GetContinuousStates", |f, c| unsafe {
            (f.fmi2GetContinuousStates)(c, out.as_mut_ptr(), out.len())
        })
    }

    /// `fmi2GetNominalsOfContinuousStates` into `out` (`nx` = its length).
    pub(crate) fn fmi2GetNominalsOfContinuousStates(&mut self, out: &mut [f64]) -> Result<()> {
        // SAFETY: `out` is writable for `out.len()` values, passed as nx.
        self.call_me("fmi2GetNominalsOfContinuousStates", |f, c| unsafe {
            (f.fmi2GetNominalsOfContinuousStates)(c, out.as_mut_ptr(), out.len())
        })
    }
}
