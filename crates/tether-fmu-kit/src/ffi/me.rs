//! The model-exchange C functions of FMI 2.0 and 3.0 (they differ only in the
//! Boolean type and in the event-info out-parameters): one generic function each,
//! called by the `#[no_mangle]` wrappers of [`crate::export_fmu!`], delegating to
//! [`crate::me`]. On a co-simulation instance every one is refused (fmi2Error).
//!
//! # Safety
//! Every function here has the contract of the FMI standard: `c` is null or a live
//! instance of `M` made by this library's instantiate functions, and every array
//! argument is null or holds the number of items given with it.

#![allow(clippy::missing_safety_doc)]

use super::{null, simple, slice, slice_mut, Fmi2Component as C, Fmi2Status as St};
use crate::instance::Instance;
use crate::machine::Call;
use crate::model::Model;

pub unsafe fn set_time<M: Model>(c: C, t: f64) -> St {
    // SAFETY: this module's contract.
    unsafe { simple::<M>(c, Call::MeSet(name::<M>(c, "SetTime")), |i| i.set_time(t)) }
}

pub unsafe fn set_continuous_states<M: Model>(c: C, x: *const f64, n: usize) -> St {
    // SAFETY: the caller guarantees n states at x.
    let x = unsafe { slice(x, n) };
    let call = Call::MeSet(name::<M>(c, "SetContinuousStates"));
    let f = |i: &mut Instance<M>| i.set_continuous_states(x.ok_or_else(|| null("x"))?);
    // SAFETY: this module's contract.
    unsafe { simple::<M>(c, call, f) }
}

/// The array-out calls: fmi2GetContinuousStates, fmi2GetDerivatives,
/// fmi2GetNominalsOfContinuousStates.
unsafe fn get_array<M: Model>(
    c: C,
    call: Call,
    out: *mut f64,
    n: usize,
    f: impl FnOnce(&mut Instance<M>, &mut [f64]) -> crate::instance::Outcome,
) -> St {
    // SAFETY: the caller guarantees n writable items at out.
    let out = unsafe { slice_mut(out, n) };
    // SAFETY: this module's contract.
    unsafe { simple::<M>(c, call, |i| f(i, out.ok_or_else(|| null("the array"))?)) }
}

pub unsafe fn get_continuous_states<M: Model>(c: C, x: *mut f64, n: usize) -> St {
    let call = Call::MeGet(name::<M>(c, "GetContinuousStates"));
    // SAFETY: this module's contract.
    unsafe { get_array::<M>(c, call, x, n, |i, x| i.get_continuous_states(x)) }
}

/// fmi2GetDerivatives / fmi3GetContinuousStateDerivatives.
pub unsafe fn get_derivatives<M: Model>(c: C, dx: *mut f64, n: usize) -> St {
    let call = Call::MeGet(name::<M>(c, "GetDerivatives"));
    // SAFETY: this module's contract.
    unsafe { get_array::<M>(c, call, dx, n, |i, dx| i.get_derivatives(dx)) }
}

pub unsafe fn get_nominals<M: Model>(c: C, nominals: *mut f64, n: usize) -> St {
    let call = Call::MeGet(name::<M>(c, "GetNominalsOfContinuousStates"));
    // SAFETY: this module's contract.
    unsafe { get_array::<M>(c, call, nominals, n, |i, v| i.get_nominals(v)) }
}

pub unsafe fn get_event_indicators<M: Model>(c: C, _z: *mut f64, n: usize) -> St {
    let call = Call::MeGet(name::<M>(c, "GetEventIndicators"));
    // SAFETY: this module's contract.
    unsafe { simple::<M>(c, call, |i| i.get_event_indicators(n)) }
}

/// fmi2EnterEventMode, fmi2EnterContinuousTimeMode and their fmi3 namesakes.
pub unsafe fn change_mode<M: Model>(c: C, function: &'static str) -> St {
    // SAFETY: this module's contract.
    unsafe { simple::<M>(c, Call::MeSet(name::<M>(c, function)), |i| i.change_mode()) }
}

/// fmi3GetNumberOfContinuousStates / fmi3GetNumberOfEventIndicators.
pub unsafe fn get_number<M: Model>(
    c: C,
    function: &'static str,
    n: *mut usize,
    value: usize,
) -> St {
    // SAFETY: the caller guarantees a writable size_t at a non-null n.
    let out = unsafe { slice_mut(n, 1) };
    let f = |_: &mut Instance<M>| {
        out.ok_or_else(|| null("the count"))?[0] = value;
        Ok(())
    };
    // SAFETY: this module's contract.
    unsafe { simple::<M>(c, Call::MeInfo(function), f) }
}

/// Writes `value` to each non-null flag (the standard's optional out-arguments).
///
/// # Safety
/// Every non-null pointer must be writable.
unsafe fn write_flags<B: Copy>(flags: &[*mut B], value: B) {
    for &p in flags {
        if !p.is_null() {
            // SAFETY: non-null and writable (the caller's contract).
            unsafe { p.write(value) };
        }
    }
}

/// fmi2CompletedIntegratorStep / fmi3CompletedIntegratorStep: event mode is never
/// needed; `terminate` says whether the model asks to end the simulation.
pub unsafe fn completed_integrator_step<M: Model, B: Copy + From<bool>>(
    c: C,
    enter_event_mode: *mut B,
    terminate: *mut B,
) -> St {
    let call = Call::MeSet(name::<M>(c, "CompletedIntegratorStep"));
    let f = |i: &mut Instance<M>| {
        if enter_event_mode.is_null() || terminate.is_null() {
            return Err(null("enterEventMode or terminateSimulation"));
        }
        let end = i.completed_integrator_step()?;
        // SAFETY: both non-null, writable by the FMI contract.
        unsafe {
            write_flags(&[enter_event_mode], B::from(false));
            write_flags(&[terminate], B::from(end));
        }
        Ok(())
    };
    // SAFETY: this module's contract.
    unsafe { simple::<M>(c, call, f) }
}

/// fmi2EventInfo.
#[repr(C)]
pub struct Fmi2EventInfo {
    pub new_discrete_states_needed: super::Fmi2Boolean,
    pub terminate_simulation: super::Fmi2Boolean,
    pub nominals_of_continuous_states_changed: super::Fmi2Boolean,
    pub values_of_continuous_states_changed: super::Fmi2Boolean,
    pub next_event_time_defined: super::Fmi2Boolean,
    pub next_event_time: f64,
}

/// fmi2NewDiscreteStates: nothing changes, no next time event.
pub unsafe fn new_discrete_states<M: Model>(c: C, info: *mut Fmi2EventInfo) -> St {
    let f = |i: &mut Instance<M>| {
        if info.is_null() {
            return Err(null("fmi2EventInfo"));
        }
        let end = i.new_discrete_states()?;
        // SAFETY: non-null, and the FMI contract makes it a writable fmi2EventInfo.
        unsafe {
            info.write(Fmi2EventInfo {
                new_discrete_states_needed: 0,
                terminate_simulation: i32::from(end),
                nominals_of_continuous_states_changed: 0,
                values_of_continuous_states_changed: 0,
                next_event_time_defined: 0,
                next_event_time: 0.0,
            });
        }
        Ok(())
    };
    // SAFETY: this module's contract.
    unsafe { simple::<M>(c, Call::MeSet("fmi2NewDiscreteStates"), f) }
}

/// fmi3UpdateDiscreteStates: as [`new_discrete_states`], with the flags as
/// separate (optional) out-arguments.
#[allow(clippy::too_many_arguments)]
pub unsafe fn update_discrete_states<M: Model>(
    c: C,
    needs_update: *mut u8,
    terminate: *mut u8,
    nominals_changed: *mut u8,
    values_changed: *mut u8,
    next_event_time_defined: *mut u8,
    next_event_time: *mut f64,
) -> St {
    let f = |i: &mut Instance<M>| {
        let end = i.new_discrete_states()?;
        // SAFETY: each non-null pointer is writable by the FMI 3.0 contract.
        unsafe {
            write_flags(
                &[
                    needs_update,
                    nominals_changed,
                    values_changed,
                    next_event_time_defined,
                ],
                0,
            );
            write_flags(&[terminate], u8::from(end));
            write_flags(&[next_event_time], 0.0);
        }
        Ok(())
    };
    // SAFETY: this module's contract.
    unsafe { simple::<M>(c, Call::MeSet("fmi3UpdateDiscreteStates"), f) }
}

/// The FMI function name of `suffix` in the instance's FMI version (fmi2GetDerivatives
/// is fmi3GetContinuousStateDerivatives).
fn name<M: Model>(c: C, suffix: &'static str) -> &'static str {
    // SAFETY: the module's contract: c is null or a live instance of M; only a
    // flag is read.
    let fmi3 = !c.is_null() && unsafe { super::is_fmi3::<M>(c) };
    match (fmi3, suffix) {
        (false, "SetTime") => "fmi2SetTime",
        (false, "SetContinuousStates") => "fmi2SetContinuousStates",
        (false, "GetContinuousStates") => "fmi2GetContinuousStates",
        (false, "GetDerivatives") => "fmi2GetDerivatives",
        (false, "GetNominalsOfContinuousStates") => "fmi2GetNominalsOfContinuousStates",
        (false, "GetEventIndicators") => "fmi2GetEventIndicators",
        (false, "CompletedIntegratorStep") => "fmi2CompletedIntegratorStep",
        (true, "SetTime") => "fmi3SetTime",
        (true, "SetContinuousStates") => "fmi3SetContinuousStates",
        (true, "GetContinuousStates") => "fmi3GetContinuousStates",
        (true, "GetDerivatives") => "fmi3GetContinuousStateDerivatives",
        (true, "GetNominalsOfContinuousStates") => "fmi3GetNominalsOfContinuousStates",
        (true, "GetEventIndicators") => "fmi3GetEventIndicators",
        (true, "CompletedIntegratorStep") => "fmi3CompletedIntegratorStep",
        (_, function) => function,
    }
}
