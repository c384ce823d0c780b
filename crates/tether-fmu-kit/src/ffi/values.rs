//! Value access, input/output derivatives, stepping and status queries: one function
//! per fmi2 function, called by the wrappers of [`crate::export_fmu!`].
//!
//! # Safety
//! Every function here has the same contract: `c` is null or a live instance of `M`
//! made by [`super::instantiate`], and every array argument is null or holds the
//! number of items the FMI standard says.

#![allow(clippy::missing_safety_doc)]

use std::ffi::{c_char, c_int};

use super::{get_values, null, set_values, simple, slice, slice_mut, with_instance};
use super::{Fmi2Boolean, Fmi2Component, Fmi2Status, Fmi2String, Fmi2ValueReference, FMI2_TRUE};
use crate::instance::{Failure, Instance};
use crate::machine::Call;
use crate::model::Model;

type Vr = *const Fmi2ValueReference;

const STATUS_KIND_LAST_SUCCESSFUL_TIME: c_int = 2;
const STATUS_KIND_TERMINATED: c_int = 3;

pub unsafe fn setup_experiment<M: Model>(
    c: Fmi2Component,
    tolerance_defined: Fmi2Boolean,
    tolerance: f64,
    start_time: f64,
    stop_time_defined: Fmi2Boolean,
    stop_time: f64,
) -> Fmi2Status {
    let tolerance = (tolerance_defined == FMI2_TRUE).then_some(tolerance);
    let stop = (stop_time_defined == FMI2_TRUE).then_some(stop_time);
    // SAFETY: this function's contract (module docs).
    unsafe {
        simple::<M>(c, Call::SetupExperiment, |i| {
            i.setup_experiment(tolerance, start_time, stop)
        })
    }
}

pub unsafe fn enter_initialization_mode<M: Model>(c: Fmi2Component) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe {
        simple::<M>(
            c,
            Call::EnterInitializationMode,
            Instance::enter_initialization_mode,
        )
    }
}

pub unsafe fn exit_initialization_mode<M: Model>(c: Fmi2Component) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe {
        simple::<M>(
            c,
            Call::ExitInitializationMode,
            Instance::exit_initialization_mode,
        )
    }
}

pub unsafe fn terminate<M: Model>(c: Fmi2Component) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe { simple::<M>(c, Call::Terminate, Instance::terminate) }
}

pub unsafe fn reset<M: Model>(c: Fmi2Component) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe { simple::<M>(c, Call::Reset, Instance::reset) }
}

pub unsafe fn get_real<M: Model>(
    c: Fmi2Component,
    vr: Vr,
    n: usize,
    value: *mut f64,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe { get_values::<M, f64>(c, Call::GetReal, vr, n, value, Instance::get_real) }
}

pub unsafe fn set_real<M: Model>(
    c: Fmi2Component,
    vr: Vr,
    n: usize,
    value: *const f64,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe { set_values::<M, f64>(c, Call::SetReal, vr, n, value, Instance::set_real) }
}

pub unsafe fn get_integer<M: Model>(
    c: Fmi2Component,
    vr: Vr,
    n: usize,
    value: *mut c_int,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe { get_values::<M, c_int>(c, Call::GetInteger, vr, n, value, Instance::get_integer) }
}

pub unsafe fn set_integer<M: Model>(
    c: Fmi2Component,
    vr: Vr,
    n: usize,
    value: *const c_int,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe { set_values::<M, c_int>(c, Call::SetInteger, vr, n, value, Instance::set_integer) }
}

pub unsafe fn get_boolean<M: Model>(
    c: Fmi2Component,
    vr: Vr,
    n: usize,
    value: *mut Fmi2Boolean,
) -> Fmi2Status {
    let get = |inst: &mut Instance<M>, vrs: &[u32], out: &mut [Fmi2Boolean]| {
        let mut values = vec![false; vrs.len()];
        inst.get_boolean(vrs, &mut values)?;
        out.iter_mut()
            .zip(values)
            .for_each(|(o, v)| *o = Fmi2Boolean::from(v));
        Ok(())
    };
    // SAFETY: this function's contract (module docs).
    unsafe { get_values::<M, Fmi2Boolean>(c, Call::GetBoolean, vr, n, value, get) }
}

pub unsafe fn set_boolean<M: Model>(
    c: Fmi2Component,
    vr: Vr,
    n: usize,
    value: *const Fmi2Boolean,
) -> Fmi2Status {
    let set = |inst: &mut Instance<M>, vrs: &[u32], values: &[Fmi2Boolean]| {
        let values: Vec<bool> = values.iter().map(|&v| v != 0).collect();
        inst.set_boolean(vrs, &values)
    };
    // SAFETY: this function's contract (module docs).
    unsafe { set_values::<M, Fmi2Boolean>(c, Call::SetBoolean, vr, n, value, set) }
}

pub unsafe fn get_string<M: Model>(
    c: Fmi2Component,
    vr: Vr,
    n: usize,
    value: *mut Fmi2String,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe {
        get_values::<M, Fmi2String>(c, Call::GetString, vr, n, value, |i, vrs, _| i.strings(vrs))
    }
}

pub unsafe fn set_string<M: Model>(
    c: Fmi2Component,
    vr: Vr,
    n: usize,
    value: *const Fmi2String,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe {
        set_values::<M, Fmi2String>(c, Call::SetString, vr, n, value, |i, vrs, _| i.strings(vrs))
    }
}

pub unsafe fn set_real_input_derivatives<M: Model>(
    c: Fmi2Component,
    vr: Vr,
    n: usize,
    order: *const c_int,
    value: *const f64,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs): n orders.
    let orders = unsafe { slice(order, n) };
    let set = |inst: &mut Instance<M>, vrs: &[u32], values: &[f64]| {
        if !M::DECLARATION.capabilities.can_interpolate_inputs {
            return Err(Failure::usage(
                "input derivatives are not supported (canInterpolateInputs=\"false\")",
            ));
        }
        inst.set_real_input_derivatives(vrs, orders.ok_or_else(|| null("order"))?, values)
    };
    // SAFETY: this function's contract (module docs).
    unsafe { set_values::<M, f64>(c, Call::SetRealInputDerivatives, vr, n, value, set) }
}

pub unsafe fn get_real_output_derivatives<M: Model>(
    c: Fmi2Component,
    vr: Vr,
    n: usize,
    order: *const c_int,
    value: *mut f64,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs): n orders.
    let orders = unsafe { slice(order, n) };
    let get = |inst: &mut Instance<M>, vrs: &[u32], values: &mut [f64]| {
        inst.get_real_output_derivatives(vrs, orders.ok_or_else(|| null("order"))?, values)
    };
    // SAFETY: this function's contract (module docs).
    unsafe { get_values::<M, f64>(c, Call::GetRealOutputDerivatives, vr, n, value, get) }
}

pub unsafe fn get_directional_derivative<M: Model>(c: Fmi2Component) -> Fmi2Status {
    let unsupported = |_: &mut Instance<M>| {
        Err(Failure::usage(
            "directional derivatives are not supported (providesDirectionalDerivative=\"false\")",
        ))
    };
    // SAFETY: this function's contract (module docs).
    unsafe { simple::<M>(c, Call::GetDirectionalDerivative, unsupported) }
}

pub unsafe fn do_step<M: Model>(
    c: Fmi2Component,
    t: f64,
    h: f64,
    _no_set_fmu_state_prior: Fmi2Boolean,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe { simple::<M>(c, Call::DoStep, |i| i.do_step(t, h)) }
}

pub unsafe fn cancel_step<M: Model>(c: Fmi2Component) -> Fmi2Status {
    // Allowed only in StepInProgress, which never happens: the table refuses it.
    // SAFETY: this function's contract (module docs).
    unsafe { simple::<M>(c, Call::CancelStep, |_| Ok(())) }
}

/// Writes `answer.1` to `value` if `kind == answer.0`, else fmi2Discard.
unsafe fn status_query<M: Model, T: Copy>(
    c: Fmi2Component,
    call: Call,
    kind: c_int,
    value: *mut T,
    answer: impl FnOnce(&Instance<M>) -> Option<(c_int, T)>,
) -> Fmi2Status {
    // SAFETY: value is null or writable (this function's contract); one item.
    let out = unsafe { slice_mut(value, 1) };
    // SAFETY: this function's contract (module docs).
    unsafe {
        with_instance::<M>(c, call, |inst| {
            let out = out.ok_or_else(|| null("value"))?;
            match answer(inst) {
                Some((k, v)) if k == kind => {
                    out[0] = v;
                    Ok(())
                }
                _ => Err(Failure::discard(format!(
                    "status kind {kind} is not available"
                ))),
            }
        })
    }
}

pub unsafe fn get_status<M: Model>(
    c: Fmi2Component,
    kind: c_int,
    value: *mut Fmi2Status,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe { status_query::<M, Fmi2Status>(c, Call::GetStatus, kind, value, |_| None) }
}

pub unsafe fn get_real_status<M: Model>(
    c: Fmi2Component,
    kind: c_int,
    value: *mut f64,
) -> Fmi2Status {
    let answer = |i: &Instance<M>| Some((STATUS_KIND_LAST_SUCCESSFUL_TIME, i.data.time));
    // SAFETY: this function's contract (module docs).
    unsafe { status_query::<M, f64>(c, Call::GetRealStatus, kind, value, answer) }
}

pub unsafe fn get_integer_status<M: Model>(
    c: Fmi2Component,
    kind: c_int,
    value: *mut c_int,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe { status_query::<M, c_int>(c, Call::GetIntegerStatus, kind, value, |_| None) }
}

pub unsafe fn get_boolean_status<M: Model>(
    c: Fmi2Component,
    kind: c_int,
    value: *mut Fmi2Boolean,
) -> Fmi2Status {
    // True once the model asked to end the simulation (Model::terminate).
    // SAFETY: this function's contract (module docs).
    unsafe {
        status_query::<M, Fmi2Boolean>(c, Call::GetBooleanStatus, kind, value, |i| {
            Some((STATUS_KIND_TERMINATED, Fmi2Boolean::from(i.terminated)))
        })
    }
}

pub unsafe fn get_string_status<M: Model>(
    c: Fmi2Component,
    kind: c_int,
    value: *mut *const c_char,
) -> Fmi2Status {
    // SAFETY: this function's contract (module docs).
    unsafe { status_query::<M, *const c_char>(c, Call::GetStringStatus, kind, value, |_| None) }
}
