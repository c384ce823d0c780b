//! The FMI 3.0 co-simulation C layer (`tether fmu export --fmi 3`): every
//! `fmi3*` function, over the same instance ([`crate::ffi::Component`],
//! [`crate::runtime::Exported`]) and the same [`with`] as the FMI 2.0 layer.
//! The FMU-state functions have the fmi2 signatures and are the fmi2
//! functions; an FMI 3.0 instance is marked, so its messages name the fmi3
//! functions. The variables are the `[export]` ones (Float64, value reference
//! = index) and `time`, the independent variable, after them. What the FMU
//! does not offer (other variable types, event mode, clocks, derivatives,
//! model exchange) returns fmi3Error with a message naming the function.

#![allow(non_snake_case, clippy::missing_safety_doc, clippy::too_many_arguments)]

use std::ffi::{c_char, c_void};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::ptr;

use tether_fmu_kit::ffi::fmi3::{
    Fmi3Boolean as B, Fmi3IntermediateUpdateCallback, Fmi3LogMessageCallback, Fmi3Status as St,
    Fmi3String as Str, Fmi3ValueReference,
};
use tether_fmu_kit::ffi::{null, slice, slice_mut};
use tether_fmu_kit::instance::{Failure, Outcome};
use tether_fmu_kit::machine::{Call, MachineState};

use crate::ffi::{
    self as f2, c_string, instantiate, intermediate_update, set_intermediate, text, with, Logger,
    ERROR, OK,
};
use crate::runtime::Exported;

type C = *mut c_void;
type S = *mut c_void;
type Vr = *const Fmi3ValueReference;

const TRUE: B = 1;
const FALSE: B = 0;

#[unsafe(no_mangle)]
pub extern "C" fn fmi3GetVersion() -> *const c_char {
    tether_fmu_kit::ffi::fmi3::get_version()
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3SetDebugLogging(c: C, on: B, n: usize, categories: *const Str) -> St {
    // SAFETY: the FMI contract (a live instance or null).
    unsafe { f2::fmi2SetDebugLogging(c, i32::from(on), n, categories) }
}

/// Null with a logged reason when the resources are missing or broken or
/// the instantiation token is not the system file's. Event mode and early
/// return are not offered (`hasEventMode="false"`): asking for them changes
/// nothing, as the standard allows. An intermediate update callback is
/// called in every inner step of `fmi3DoStep` (see there).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3InstantiateCoSimulation(
    name: Str,
    token: Str,
    resources: Str,
    _visible: B,
    logging_on: B,
    _event_mode_used: B,
    _early_return_allowed: B,
    _required_intermediate: Vr,
    _n_required_intermediate: usize,
    environment: *mut c_void,
    log_message: Fmi3LogMessageCallback,
    intermediate_update: Fmi3IntermediateUpdateCallback,
) -> C {
    let made = catch_unwind(AssertUnwindSafe(|| {
        // SAFETY: the FMI contract: a NUL-terminated name or null.
        let Some(name) = (unsafe { text(name) }) else {
            return ptr::null_mut();
        };
        let logger = log_message.map(|callback| Logger::Fmi3 {
            callback,
            environment,
        });
        // SAFETY: the FMI contract: NUL-terminated strings or null.
        let (token, resources) = unsafe { (text(token), text(resources)) };
        // FMI 3.0 gives the resources folder as a path, not a URI.
        let resources = resources
            .map(PathBuf::from)
            .ok_or_else(|| "no resourcePath given".to_string());
        instantiate(
            c_string(&name),
            logger,
            logging_on == TRUE,
            Some(intermediate_update.map(|callback| (callback, environment))),
            resources,
            token,
        )
    }));
    made.unwrap_or(ptr::null_mut())
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3FreeInstance(c: C) {
    // SAFETY: the FMI contract (see `with`).
    unsafe { f2::fmi2FreeInstance(c) }
}

/// The experiment (fmi2SetupExperiment's arguments), then initialization
/// mode, as one call.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3EnterInitializationMode(
    c: C,
    _tol_defined: B,
    _tol: f64,
    start: f64,
    stop_defined: B,
    stop: f64,
) -> St {
    let stop = (stop_defined == TRUE).then_some(stop);
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::EnterInitializationMode, |e| {
            e.setup_experiment(start, stop)?;
            e.machine = MachineState::InitializationMode;
            Ok(())
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3ExitInitializationMode(c: C) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe { f2::fmi2ExitInitializationMode(c) }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3Terminate(c: C) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe { f2::fmi2Terminate(c) }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3Reset(c: C) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe { f2::fmi2Reset(c) }
}

/// `nValues` must equal `nValueReferences`: every variable is a scalar.
fn scalars(n: usize, n_values: usize) -> Outcome {
    if n == n_values {
        Ok(())
    } else {
        Err(Failure::usage(format!(
            "nValues is {n_values}, expected {n} (every variable is a scalar)"
        )))
    }
}

/// The value reference of `time`: the one after the exported variables.
fn is_time(e: &Exported, vr: u32) -> bool {
    vr as usize == e.variable_count()
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3GetFloat64(c: C, vr: Vr, n: usize, v: *mut f64, nv: usize) -> St {
    // SAFETY: the FMI contract: n value references and nv writable values.
    let (vr, v) = unsafe { (slice(vr, n), slice_mut(v, nv)) };
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::GetReal, |e| {
            scalars(n, nv)?;
            let (vr, v) = (
                vr.ok_or_else(|| null("vr"))?,
                v.ok_or_else(|| null("values"))?,
            );
            if !vr.iter().any(|&r| is_time(e, r)) {
                return e.get_real(vr, v);
            }
            for (&r, value) in vr.iter().zip(v.iter_mut()) {
                if is_time(e, r) {
                    *value = e.time().unwrap_or(e.start_time());
                } else {
                    e.get_real(&[r], std::slice::from_mut(value))?;
                }
            }
            Ok(())
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3SetFloat64(c: C, vr: Vr, n: usize, v: *const f64, nv: usize) -> St {
    // SAFETY: the FMI contract: n value references and nv values.
    let (vr, v) = unsafe { (slice(vr, n), slice(v, nv)) };
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::SetReal, |e| {
            scalars(n, nv)?;
            let (vr, v) = (
                vr.ok_or_else(|| null("vr"))?,
                v.ok_or_else(|| null("values"))?,
            );
            if vr.iter().any(|&r| is_time(e, r)) {
                return Err(Failure::usage(
                    "time is the independent variable: it cannot be set",
                ));
            }
            e.set_real(vr, v)
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3GetFMUState(c: C, s: *mut S) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe { f2::fmi2GetFMUstate(c, s) }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3SetFMUState(c: C, s: S) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe { f2::fmi2SetFMUstate(c, s) }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3FreeFMUState(c: C, s: *mut S) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe { f2::fmi2FreeFMUstate(c, s) }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3SerializedFMUStateSize(c: C, s: S, size: *mut usize) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe { f2::fmi2SerializedFMUstateSize(c, s, size) }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3SerializeFMUState(c: C, s: S, bytes: *mut u8, size: usize) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe { f2::fmi2SerializeFMUstate(c, s, bytes.cast(), size) }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3DeserializeFMUState(
    c: C,
    bytes: *const u8,
    size: usize,
    s: *mut S,
) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe { f2::fmi2DeSerializeFMUstate(c, bytes.cast(), size, s) }
}

/// The macro steps over [t, t + h] (see [`Exported::do_step`]). No event
/// handling and no early return; `lastSuccessfulTime` is the system's time
/// after the call, also after a failed step.
///
/// With the importer's intermediate update callback, each inner macro step
/// starts with a call back at its start time τ (intermediateVariableSetRequested
/// true, intermediateVariableGetAllowed false, intermediateStepFinished true:
/// the point at τ is accepted, canReturnEarly false), in which the importer
/// sets the inputs (`fmi3SetFloat64`) for that time; they hold over that
/// inner step. Without a callback the inputs are held over the whole step.
/// No reference to the instance is live while the callback runs.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi3DoStep(
    c: C,
    t: f64,
    h: f64,
    _no_set_fmu_state_prior: B,
    event_handling_needed: *mut B,
    terminate_simulation: *mut B,
    early_return: *mut B,
    last_successful_time: *mut f64,
) -> St {
    // SAFETY: the FMI contract: each out-pointer is null or one writable item.
    let outs = unsafe {
        (
            slice_mut(event_handling_needed, 1),
            slice_mut(terminate_simulation, 1),
            slice_mut(early_return, 1),
            slice_mut(last_successful_time, 1),
        )
    };
    let (Some(event), Some(terminate), Some(early), Some(last)) = outs else {
        // SAFETY: the FMI contract (see `with`).
        return unsafe {
            with(c, Call::DoStep, |_| {
                Err(null("an output argument of fmi3DoStep"))
            })
        };
    };
    event[0] = 0;
    terminate[0] = 0;
    early[0] = 0;
    // One part of the step: `lastSuccessfulTime` follows the system's time.
    let mut part = |f: &mut dyn FnMut(&mut Exported) -> Outcome| {
        // SAFETY: the FMI contract (see `with`).
        unsafe {
            with(c, Call::DoStep, |e| {
                let result = f(e);
                last[0] = e.time().unwrap_or(t);
                result
            })
        }
    };
    // SAFETY: the FMI contract (see `with`).
    let Some((callback, environment)) = (unsafe { intermediate_update(c) }) else {
        return part(&mut |e| e.do_step(t, h));
    };
    let mut step = None;
    let status = part(&mut |e| {
        step = Some(e.begin_step(t, h)?);
        Ok(())
    });
    let Some(mut step) = step.filter(|_| status == OK) else {
        return status;
    };
    loop {
        let mut next = None;
        let status = part(&mut |e| {
            next = e.next_inner_step(&step)?;
            Ok(())
        });
        if status != OK {
            return status;
        }
        let Some(tau) = next else {
            break;
        };
        let (mut early_requested, mut early_time) = (0, tau);
        // SAFETY: the importer's callback with the environment it gave to
        // fmi3InstantiateCoSimulation and two writable out-arguments; no
        // reference to the instance is held across the call (it calls
        // fmi3SetFloat64 on this instance), which `with` refuses anything
        // but setting inputs meanwhile.
        unsafe {
            set_intermediate(c, true);
            callback(
                environment,
                tau,
                TRUE,
                FALSE,
                TRUE,
                FALSE,
                &mut early_requested,
                &mut early_time,
            );
            set_intermediate(c, false);
        }
        let status = part(&mut |e| e.inner_step(&mut step));
        if status != OK {
            return status;
        }
    }
    part(&mut |e| e.end_step(&step))
}

/// A function the FMU does not offer: fmi3Error with a message naming it.
unsafe fn unsupported(c: C, function: &'static str) -> St {
    if c.is_null() {
        return ERROR;
    }
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::Unsupported(function), |_| {
            Err(Failure::usage(
                "not supported by this FMU (Float64 variables only, no event mode, clocks or derivatives)",
            ))
        })
    }
}

// The functions of the kit's list (tether_fmu_kit::fmi3_unsupported!), and
// those the kit offers but this FMU does not: step mode (no event mode),
// Int32 and Boolean variables, output derivatives.
tether_fmu_kit::fmi3_unsupported! {
    unsupported;
    fmi3EnterStepMode();
    fmi3GetInt32(Vr, usize, *mut i32, usize);
    fmi3GetBoolean(Vr, usize, *mut B, usize);
    fmi3SetInt32(Vr, usize, *const i32, usize);
    fmi3SetBoolean(Vr, usize, *const B, usize);
    fmi3GetOutputDerivatives(Vr, usize, *const i32, *mut f64, usize);
}

/// Model exchange and scheduled execution are not offered (the model
/// description has only `<CoSimulation>`): no instance.
#[unsafe(no_mangle)]
pub extern "C" fn fmi3InstantiateModelExchange(
    _name: Str,
    _token: Str,
    _resources: Str,
    _visible: B,
    _logging_on: B,
    _environment: *mut c_void,
    _log_message: Fmi3LogMessageCallback,
) -> C {
    ptr::null_mut()
}

#[unsafe(no_mangle)]
pub extern "C" fn fmi3InstantiateScheduledExecution(
    _name: Str,
    _token: Str,
    _resources: Str,
    _visible: B,
    _logging_on: B,
    _environment: *mut c_void,
    _log_message: Fmi3LogMessageCallback,
    _clock_update: *mut c_void,
    _lock_preemption: *mut c_void,
    _unlock_preemption: *mut c_void,
) -> C {
    ptr::null_mut()
}
