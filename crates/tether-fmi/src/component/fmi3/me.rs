//! The FMI 3.0 model-exchange functions of [`RawInstance3`], one-to-one under their
//! C names, each through the fatal-state guard and the status check.

use super::{boolean, RawInstance3};
use crate::component::fmi2::EventInfo;
use crate::error::Result;
use crate::raw::fmi3::*;
use crate::raw::Fmi3MeFunctions;

impl RawInstance3 {
    /// Runs a model-exchange function: refused (naming it) when the library
    /// lacks the model-exchange functions, else as every call.
    #[inline]
    fn call_me(
        &mut self,
        function: &'static str,
        call: impl FnOnce(&Fmi3MeFunctions, fmi3Instance) -> fmi3Status,
    ) -> Result<()> {
        let library = std::sync::Arc::clone(&self.library);
        let me = library.me()?;
        self.call(function, |_, c| call(me, c))
    }

    /// `fmi3EnterEventMode`.
    pub(crate) fn fmi3EnterEventMode(&mut self) -> Result<()> {
        // SAFETY: the instance is live.
        self.call_me("fmi3EnterEventMode", |f, c| unsafe {
            (f.fmi3EnterEventMode)(c)
        })
    }

    /// `fmi3UpdateDiscreteStates`.
    pub(crate) fn fmi3UpdateDiscreteStates(&mut self) -> Result<EventInfo> {
        let (mut again, mut terminate, mut nominals, mut values, mut defined) =
            (fmi3False, fmi3False, fmi3False, fmi3False, fmi3False);
        let mut next = 0.0;
        // SAFETY: every out-pointer is valid for the call's duration.
        self.call_me("fmi3UpdateDiscreteStates", |f, c| unsafe {
            (f.fmi3UpdateDiscreteStates)(
                c,
                &mut again,
                &mut terminate,
                &mut nominals,
                &mut values,
                &mut defined,
                &mut next,
            )
        })?;
        Ok(EventInfo {
            new_discrete_states_needed: again != fmi3False,
            terminate_simulation: terminate != fmi3False,
            nominals_changed: nominals != fmi3False,
            values_changed: values != fmi3False,
            next_event_time: (defined != fmi3False).then_some(next),
        })
    }

    /// `fmi3EnterContinuousTimeMode`.
    pub(crate) fn fmi3EnterContinuousTimeMode(&mut self) -> Result<()> {
        // SAFETY: the instance is live.
        self.call_me("fmi3EnterContinuousTimeMode", |f, c| unsafe {
            (f.fmi3EnterContinuousTimeMode)(c)
        })
    }

    /// `fmi3CompletedIntegratorStep`: (enterEventMode, terminateSimulation).
    pub(crate) fn fmi3CompletedIntegratorStep(
        &mut self,
        no_set_fmu_state_prior: bool,
    ) -> Result<(bool, bool)> {
        let (mut event, mut terminate) = (fmi3False, fmi3False);
        // SAFETY: both out-pointers are valid for the call's duration.
        self.call_me("fmi3CompletedIntegratorStep", |f, c| unsafe {
            (f.fmi3CompletedIntegratorStep)(
                c,
                boolean(no_set_fmu_state_prior),
                &mut event,
                &mut terminate,
            )
        })?;
        Ok((event != fmi3False, terminate != fmi3False))
    }

    /// `fmi3SetTime`.
    pub(crate) fn fmi3SetTime(&mut self, time: f64) -> Result<()> {
        // SAFETY: scalar argument; the instance is live.
        self.call_me("fmi3SetTime", |f, c| unsafe { (f.fmi3SetTime)(c, time) })
    }

    /// `fmi3SetContinuousStates` (`nContinuousStates` = the length of `x`).
    pub(crate) fn fmi3SetContinuousStates(&mut self, x: &[f64]) -> Result<()> {
        // SAFETY: `x` holds `x.len()` values, passed as nContinuousStates.
        self.call_me("fmi3SetContinuousStates", |f, c| unsafe {
            (f.fmi3SetContinuousStates)(c, x.as_ptr(), x.len())
        })
    }

    /// `fmi3GetContinuousStateDerivatives` into `out` (its length passed).
    pub(crate) fn fmi3GetContinuousStateDerivatives(&mut self, out: &mut [f64]) -> Result<()> {
        // SAFETY: `out` is writable for `out.len()` values, passed as the count.
        self.call_me("fmi3GetContinuousStateDerivatives", |f, c| unsafe {
            (f.fmi3GetContinuousStateDerivatives)(c, out.as_mut_ptr(), out.len())
        })
    }

    /// `fmi3GetEventIndicators` into `out` (its length passed).
    pub(crate) fn fmi3GetEventIndicators(&mut self, out: &mut [f64]) -> Result<()> {
        // SAFETY: `out` is writable for `out.len()` values, passed as the count.
        self.call_me("fmi3GetEventIndicators", |f, c| unsafe {
            (f.fmi3GetEventIndicators)(c, out.as_mut_ptr(), out.len())
        })
    }

    /// `fmi3GetContinuousStates` into `out` (its length passed).
    pub(crate) fn fmi3GetContinuousStates(&mut self, out: &mut [f64]) -> Result<()> {
        // SAFETY: `out` is writable for `out.len()` values, passed as the count.
        self.call_me("fmi3GetContinuousStates", |f, c| unsafe {
            (f.fmi3GetContinuousStates)(c, out.as_mut_ptr(), out.len())
        })
    }

    /// `fmi3GetNominalsOfContinuousStates` into `out` (its length passed).
    pub(crate) fn fmi3GetNominalsOfContinuousStates(&mut self, out: &mut [f64]) -> Result<()> {
        // SAFETY: `out` is writable for `out.len()` values, passed as the count.
        self.call_me("fmi3GetNominalsOfContinuousStates", |f, c| unsafe {
            (f.fmi3GetNominalsOfContinuousStates)(c, out.as_mut_ptr(), out.len())
        })
    }

    /// `fmi3GetNumberOfContinuousStates`.
    pub(crate) fn fmi3GetNumberOfContinuousStates(&mut self) -> Result<usize> {
        let mut n = 0;
        // SAFETY: `n` is a valid out-pointer for the call's duration.
        self.call_me("fmi3GetNumberOfContinuousStates", |f, c| unsafe {
            (f.fmi3GetNumberOfContinuousStates)(c, &mut n)
        })?;
        Ok(n)
    }

    /// `fmi3GetNumberOfEventIndicators`.
    pub(crate) fn fmi3GetNumberOfEventIndicators(&mut self) -> Result<usize> {
        let mut n = 0;
        // SAFETY: `n` is a valid out-pointer for the call's duration.
        self.call_me("fmi3GetNumberOfEventIndicators", |f, c| unsafe {
            (f.fmi3GetNumberOfEventIndicators)(c, &mut n)
        })?;
        Ok(n)
    }

    /// `fmi3GetDirectionalDerivative` of scalar variables: `sensitivity =
    /// ∂unknowns/∂knowns · seed` (nSeed = the number of knowns, nSensitivity
    /// the number of unknowns).
    pub(crate) fn fmi3GetDirectionalDerivative(
        &mut self,
        unknowns: &[fmi3ValueReference],
        knowns: &[fmi3ValueReference],
        seed: &[f64],
        sensitivity: &mut [f64],
    ) -> Result<()> {
        const F: &str = "fmi3GetDirectionalDerivative";
        let (what, expected, got) = if seed.len() != knowns.len() {
            ("the seed slice", knowns.len(), seed.len())
        } else {
            ("the sensitivity slice", unknowns.len(), sensitivity.len())
        };
        if expected != got {
            return Err(crate::error::Error::LengthMismatch {
                function: F,
                instance: self.name().to_owned(),
                what,
                expected,
                got,
            });
        }
        // SAFETY: each array has the length passed with it (checked above).
        self.call_me(F, |f, c| unsafe {
            (f.fmi3GetDirectionalDerivative)(
                c,
                unknowns.as_ptr(),
                unknowns.len(),
                knowns.as_ptr(),
                knowns.len(),
                seed.as_ptr(),
                seed.len(),
                sensitivity.as_mut_ptr(),
                sensitivity.len(),
            )
        })
    }
}
