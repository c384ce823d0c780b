//! The FMI 3.0 co-simulation C layer: one generic function per fmi3 function that
//! differs from its fmi2 counterpart, called by the `#[no_mangle]` wrappers that
//! [`crate::export_fmu!`] generates next to the fmi2 ones. The model, the
//! [`Instance`] and its state machine are the same; an FMI 3.0 instance is marked
//! ([`Instance::fmi3`]) so that its messages name the fmi3 functions. The FMU-state
//! functions have the fmi2 signatures and are shared ([`super::get_fmu_state`], …).
//!
//! # Safety
//! Every function here has the contract of the FMI 3.0 standard: `c` is null or a
//! live instance of `M` made by [`instantiate_co_simulation`], and every array
//! argument is null or holds the number of items the standard says.

#![allow(clippy::missing_safety_doc)]

use std::ffi::{c_char, c_void, CStr};
use std::panic::catch_unwind;
use std::ptr;

use super::{
    c_string, get_values, null, set_values, simple, slice, slice_mut, with_instance, Component,
    EnvironmentLogger, Fmi2Component as Fmi3Instance, ERROR,
};
use crate::instance::{Failure, Instance, LogFn, Status};
use crate::machine::Call;
use crate::model::Model;
use crate::xml;

pub type Fmi3Status = i32;
/// `fmi3Boolean` is C's `bool`: one byte, 0 or 1.
pub type Fmi3Boolean = u8;
pub type Fmi3ValueReference = u32;
pub type Fmi3String = *const c_char;

/// `fmi3LogMessageCallback`.
pub type Fmi3LogMessageCallback =
    Option<unsafe extern "C" fn(*mut c_void, Fmi3Status, Fmi3String, Fmi3String)>;
/// `fmi3IntermediateUpdateCallback`: called in `fmi3DoStep` to ask for the inputs
/// at intermediate times ([`do_step`]).
pub type Fmi3IntermediateUpdateCallback = Option<IntermediateUpdate>;

/// The function of a non-null [`Fmi3IntermediateUpdateCallback`].
pub type IntermediateUpdate = unsafe extern "C" fn(
    *mut c_void,
    f64,
    Fmi3Boolean,
    Fmi3Boolean,
    Fmi3Boolean,
    Fmi3Boolean,
    *mut Fmi3Boolean,
    *mut f64,
);

const TRUE: Fmi3Boolean = 1;
const FALSE: Fmi3Boolean = 0;

/// The component environment of a model's own messages in an FMI 3.0 build
/// ([`crate::environment_logger`]): `c/fmi3_logger.c` formats a message given the
/// fmi2 way and passes it to the importer's `fmi3LogMessageCallback`.
#[repr(C)]
pub struct Fmi3LogEnv {
    log: unsafe extern "C" fn(*mut c_void, Fmi3Status, Fmi3String, Fmi3String),
    instance_environment: *mut c_void,
}

extern "C" {
    /// `c/fmi3_logger.c`: the fmi2CallbackLogger signature over an [`Fmi3LogEnv`].
    fn tether_kit_fmi3_logger(
        component_environment: *mut c_void,
        instance_name: Fmi3String,
        status: Fmi3Status,
        category: Fmi3String,
        format: Fmi3String,
        ...
    );
}

pub fn get_version() -> *const c_char {
    c"3.0".as_ptr()
}

fn make_logger(logger: Fmi3LogMessageCallback, environment: *mut c_void) -> Option<LogFn> {
    let logger = logger?;
    Some(Box::new(
        move |status: Status, category: &str, message: &str| {
            let category = c_string(category);
            let message = c_string(message);
            // SAFETY: the environment promised a valid logger for the instance's
            // lifetime; both strings are NUL-terminated and live across the call.
            unsafe {
                logger(
                    environment,
                    status as Fmi3Status,
                    category.as_ptr(),
                    message.as_ptr(),
                )
            }
        },
    ))
}

/// fmi3InstantiateCoSimulation: null on any invalid argument (logged if a logger was
/// given). Event mode and early return are not offered (`hasEventMode="false"`,
/// `canReturnEarlyAfterIntermediateUpdate="false"`): asking for them is allowed and
/// changes nothing, as the standard says.
///
/// # Safety
/// Non-null string arguments must be NUL-terminated.
pub unsafe fn instantiate_co_simulation<M: Model>(
    instance_name: Fmi3String,
    token: Fmi3String,
    logging_on: Fmi3Boolean,
    environment: *mut c_void,
    log_message: Fmi3LogMessageCallback,
    intermediate_update: Fmi3IntermediateUpdateCallback,
) -> Fmi3Instance {
    // SAFETY: forwarded contract.
    unsafe {
        instantiate::<M>(
            instance_name,
            token,
            logging_on,
            environment,
            log_message,
            intermediate_update,
            false,
        )
    }
}

/// fmi3InstantiateModelExchange: as [`instantiate_co_simulation`], for a model
/// that declares model exchange ([`crate::declaration::Declaration::model_exchange`]);
/// null (and an error logged) for one that does not.
///
/// # Safety
/// Non-null string arguments must be NUL-terminated.
pub unsafe fn instantiate_model_exchange<M: Model>(
    instance_name: Fmi3String,
    token: Fmi3String,
    logging_on: Fmi3Boolean,
    environment: *mut c_void,
    log_message: Fmi3LogMessageCallback,
) -> Fmi3Instance {
    // SAFETY: forwarded contract.
    unsafe {
        instantiate::<M>(
            instance_name,
            token,
            logging_on,
            environment,
            log_message,
            None,
            true,
        )
    }
}

/// # Safety
/// Non-null string arguments must be NUL-terminated.
unsafe fn instantiate<M: Model>(
    instance_name: Fmi3String,
    token: Fmi3String,
    logging_on: Fmi3Boolean,
    environment: *mut c_void,
    log_message: Fmi3LogMessageCallback,
    intermediate_update: Fmi3IntermediateUpdateCallback,
    me: bool,
) -> Fmi3Instance {
    let function = if me {
        "fmi3InstantiateModelExchange"
    } else {
        "fmi3InstantiateCoSimulation"
    };
    let result = catch_unwind(|| {
        if instance_name.is_null() {
            return ptr::null_mut();
        }
        // SAFETY: non-null, and the caller guarantees a NUL-terminated string.
        let name = unsafe { CStr::from_ptr(instance_name) }
            .to_string_lossy()
            .into_owned();
        let mut instance = Instance::<M>::new(
            &name,
            make_logger(log_message, environment),
            logging_on == TRUE,
        )
        .fmi3();
        instance.me = me;
        if me && !M::DECLARATION.model_exchange {
            instance.log(
                Status::Error,
                &format!("{function}: this FMU supports co-simulation only"),
            );
            return ptr::null_mut();
        }
        let expected = xml::model_guid::<M>();
        // SAFETY: non-null, and the caller guarantees a NUL-terminated string.
        let token = (!token.is_null()).then(|| unsafe { CStr::from_ptr(token) }.to_string_lossy());
        if token.as_deref() != Some(expected) {
            instance.log(
                Status::Error,
                &format!(
                    "{function}: instantiationToken {token:?} does not match the model's {expected}"
                ),
            );
            return ptr::null_mut();
        }
        // A model's own messages (`environment_logger`) go through the fmi2
        // logger's signature: the C shim formats them for fmi3LogMessageCallback.
        let name = c_string(&name);
        let mut fmi3_log = log_message.map(|log| {
            Box::new(Fmi3LogEnv {
                log,
                instance_environment: environment,
            })
        });
        let logger = fmi3_log.as_mut().map(|env| {
            let env: *mut Fmi3LogEnv = &mut **env;
            EnvironmentLogger {
                logger: tether_kit_fmi3_logger,
                component_environment: env.cast(),
                instance_name: name.as_ptr(),
            }
        });
        let component = Component {
            instance,
            logger,
            intermediate_update: intermediate_update.map(|f| (f, environment)),
            _fmi3_log: fmi3_log,
            _name: name,
        };
        Box::into_raw(Box::new(component)).cast::<c_void>()
    });
    result.unwrap_or(ptr::null_mut())
}

/// fmi3EnterInitializationMode: the experiment (fmi2SetupExperiment's arguments),
/// then initialization mode, checked and applied as one call.
pub unsafe fn enter_initialization_mode<M: Model>(
    c: Fmi3Instance,
    tolerance_defined: Fmi3Boolean,
    tolerance: f64,
    start_time: f64,
    stop_time_defined: Fmi3Boolean,
    stop_time: f64,
) -> Fmi3Status {
    let tolerance = (tolerance_defined == TRUE).then_some(tolerance);
    let stop = (stop_time_defined == TRUE).then_some(stop_time);
    // SAFETY: this module's contract.
    unsafe {
        simple::<M>(c, Call::EnterInitializationMode, |i| {
            i.setup_experiment(tolerance, start_time, stop)?;
            i.enter_initialization_mode()
        })
    }
}

/// Refuses a get/set whose `nValues` differs from `nValueReferences` (every variable
/// is a scalar) before any array is touched.
#[inline]
unsafe fn scalars<M: Model>(
    c: Fmi3Instance,
    call: Call,
    n: usize,
    n_values: usize,
) -> Option<Fmi3Status> {
    // SAFETY: this module's contract.
    (n != n_values).then(|| unsafe { refuse_values::<M>(c, call, n, n_values) })
}

#[cold]
#[inline(never)]
unsafe fn refuse_values<M: Model>(
    c: Fmi3Instance,
    call: Call,
    n: usize,
    n_values: usize,
) -> Fmi3Status {
    let refuse = |_: &mut Instance<M>| {
        Err(Failure::usage(format!(
            "nValues is {n_values}, expected {n} (every variable is a scalar)"
        )))
    };
    // SAFETY: this module's contract.
    unsafe { simple::<M>(c, call, refuse) }
}

pub unsafe fn get_float64<M: Model>(
    c: Fmi3Instance,
    vr: *const Fmi3ValueReference,
    n: usize,
    values: *mut f64,
    n_values: usize,
) -> Fmi3Status {
    // SAFETY: this module's contract.
    if let Some(status) = unsafe { scalars::<M>(c, Call::GetReal, n, n_values) } {
        return status;
    }
    let get = |i: &mut Instance<M>, vrs: &[u32], out: &mut [f64]| i.get_real(vrs, out);
    // SAFETY: this module's contract.
    unsafe { get_values::<M, f64>(c, Call::GetReal, vr, n, values, get) }
}

pub unsafe fn set_float64<M: Model>(
    c: Fmi3Instance,
    vr: *const Fmi3ValueReference,
    n: usize,
    values: *const f64,
    n_values: usize,
) -> Fmi3Status {
    // SAFETY: this module's contract.
    if let Some(status) = unsafe { scalars::<M>(c, Call::SetReal, n, n_values) } {
        return status;
    }
    let set = |i: &mut Instance<M>, vrs: &[u32], values: &[f64]| i.set_real(vrs, values);
    // SAFETY: this module's contract.
    unsafe { set_values::<M, f64>(c, Call::SetReal, vr, n, values, set) }
}

pub unsafe fn get_int32<M: Model>(
    c: Fmi3Instance,
    vr: *const Fmi3ValueReference,
    n: usize,
    values: *mut i32,
    n_values: usize,
) -> Fmi3Status {
    // SAFETY: this module's contract.
    if let Some(status) = unsafe { scalars::<M>(c, Call::GetInteger, n, n_values) } {
        return status;
    }
    let get = |i: &mut Instance<M>, vrs: &[u32], out: &mut [i32]| i.get_integer(vrs, out);
    // SAFETY: this module's contract.
    unsafe { get_values::<M, i32>(c, Call::GetInteger, vr, n, values, get) }
}

pub unsafe fn set_int32<M: Model>(
    c: Fmi3Instance,
    vr: *const Fmi3ValueReference,
    n: usize,
    values: *const i32,
    n_values: usize,
) -> Fmi3Status {
    // SAFETY: this module's contract.
    if let Some(status) = unsafe { scalars::<M>(c, Call::SetInteger, n, n_values) } {
        return status;
    }
    let set = |i: &mut Instance<M>, vrs: &[u32], values: &[i32]| i.set_integer(vrs, values);
    // SAFETY: this module's contract.
    unsafe { set_values::<M, i32>(c, Call::SetInteger, vr, n, values, set) }
}

pub unsafe fn get_boolean<M: Model>(
    c: Fmi3Instance,
    vr: *const Fmi3ValueReference,
    n: usize,
    values: *mut Fmi3Boolean,
    n_values: usize,
) -> Fmi3Status {
    // SAFETY: this module's contract.
    if let Some(status) = unsafe { scalars::<M>(c, Call::GetBoolean, n, n_values) } {
        return status;
    }
    let get = |i: &mut Instance<M>, vrs: &[u32], out: &mut [Fmi3Boolean]| {
        let mut values = vec![false; vrs.len()];
        i.get_boolean(vrs, &mut values)?;
        out.iter_mut()
            .zip(values)
            .for_each(|(o, v)| *o = Fmi3Boolean::from(v));
        Ok(())
    };
    // SAFETY: this module's contract.
    unsafe { get_values::<M, Fmi3Boolean>(c, Call::GetBoolean, vr, n, values, get) }
}

pub unsafe fn set_boolean<M: Model>(
    c: Fmi3Instance,
    vr: *const Fmi3ValueReference,
    n: usize,
    values: *const Fmi3Boolean,
    n_values: usize,
) -> Fmi3Status {
    // SAFETY: this module's contract.
    if let Some(status) = unsafe { scalars::<M>(c, Call::SetBoolean, n, n_values) } {
        return status;
    }
    let set = |i: &mut Instance<M>, vrs: &[u32], values: &[Fmi3Boolean]| {
        let values: Vec<bool> = values.iter().map(|&v| v != 0).collect();
        i.set_boolean(vrs, &values)
    };
    // SAFETY: this module's contract.
    unsafe { set_values::<M, Fmi3Boolean>(c, Call::SetBoolean, vr, n, values, set) }
}

pub unsafe fn get_output_derivatives<M: Model>(
    c: Fmi3Instance,
    vr: *const Fmi3ValueReference,
    n: usize,
    orders: *const i32,
    values: *mut f64,
    n_values: usize,
) -> Fmi3Status {
    // SAFETY: this module's contract.
    if let Some(status) = unsafe { scalars::<M>(c, Call::GetRealOutputDerivatives, n, n_values) } {
        return status;
    }
    // SAFETY: this module's contract: n orders.
    let orders = unsafe { slice(orders, n) };
    let get = |i: &mut Instance<M>, vrs: &[u32], out: &mut [f64]| {
        i.get_real_output_derivatives(vrs, orders.ok_or_else(|| null("orders"))?, out)
    };
    // SAFETY: this module's contract.
    unsafe { get_values::<M, f64>(c, Call::GetRealOutputDerivatives, vr, n, values, get) }
}

/// fmi3DoStep. The kit never needs event handling and never returns early; a model
/// that asks to end the simulation ([`Model::terminate`]) sets `terminateSimulation`
/// (status fmi3Discard, as fmi2DoStep). `lastSuccessfulTime` is the FMU's time after
/// the call.
///
/// With an intermediate update callback and inputs, the step first asks for the
/// inputs at `t + h/2` and at `t + h` (intermediateVariableSetRequested, no gets,
/// intermediateStepFinished false, no early return) and takes the quadratic through
/// them and the value at `t` as the inputs' polynomial over the step
/// ([`Instance::take_intermediate_inputs`]); the model then steps as with
/// `fmi2SetRealInputDerivatives`. No reference to the instance is live while the
/// importer's callback runs (it calls `fmi3SetFloat64` on this instance). Each
/// callback is logged (logEvents): "intermediate update at t = …".
#[allow(clippy::too_many_arguments)]
pub unsafe fn do_step<M: Model>(
    c: Fmi3Instance,
    t: f64,
    h: f64,
    event_handling_needed: *mut Fmi3Boolean,
    terminate_simulation: *mut Fmi3Boolean,
    early_return: *mut Fmi3Boolean,
    last_successful_time: *mut f64,
) -> Fmi3Status {
    // SAFETY: this module's contract: each out-pointer is null or one writable item.
    let outs = unsafe {
        (
            slice_mut(event_handling_needed, 1),
            slice_mut(terminate_simulation, 1),
            slice_mut(early_return, 1),
            slice_mut(last_successful_time, 1),
        )
    };
    let (Some(event), Some(terminate), Some(early), Some(last)) = outs else {
        // SAFETY: this module's contract.
        return unsafe {
            simple::<M>(c, Call::DoStep, |_| {
                Err(null("an output argument of fmi3DoStep"))
            })
        };
    };
    event[0] = 0;
    terminate[0] = 0;
    early[0] = 0;
    // SAFETY: this module's contract.
    let sampled = unsafe { intermediate_inputs::<M>(c, t, h) };
    // SAFETY: this module's contract.
    unsafe {
        simple::<M>(c, Call::DoStep, |i| {
            if sampled {
                i.take_intermediate_inputs();
            }
            let result = i.do_step(t, h);
            terminate[0] = Fmi3Boolean::from(i.terminated);
            last[0] = i.data.time;
            result
        })
    }
}

/// The inputs the importer sets in intermediate update mode at `t + h/2` and `t + h`
/// (see [`do_step`]) into the instance's [`samples`](Instance::samples): `false`
/// without a callback, inputs or a valid step, or when the instance may not step
/// (the step then reports why).
///
/// # Safety
/// This module's contract.
unsafe fn intermediate_inputs<M: Model>(c: Fmi3Instance, t: f64, h: f64) -> bool {
    let n = M::DECLARATION.inputs.len();
    let provided = xml::intermediate_update(&M::DECLARATION);
    if c.is_null() || !provided || !(h > 0.0 && h.is_finite() && t.is_finite()) {
        return false;
    }
    let component = c.cast::<Component<M>>();
    // SAFETY: c is a live instance of M (this module's contract); the borrow ends
    // with this statement.
    let hook = unsafe { (*component).intermediate_update };
    let Some((callback, environment)) = hook else {
        return false;
    };
    for (k, time) in [t + 0.5 * h, t + h].into_iter().enumerate() {
        {
            // SAFETY: c is a live instance of M; this borrow ends with the block,
            // before the importer's callback, which borrows the instance itself
            // (fmi3SetFloat64).
            let i = unsafe { &mut (*component).instance };
            if !Call::DoStep.allowed_in(i.data.machine) {
                // Not allowed now (e.g. a call in the previous callback ended
                // fatally): the step itself reports it.
                return false;
            }
            i.log_event(|| format!("intermediate update at t = {time} (step {t} + {h})"));
            let (s, set) = &mut i.samples[k];
            *s = time - t;
            set.clear();
            set.resize(n, None);
            i.intermediate = Some(k);
        }
        let (mut early, mut early_time) = (FALSE, time);
        // SAFETY: the importer's callback with the environment it gave to
        // fmi3InstantiateCoSimulation and two writable out-arguments; no Rust
        // reference to the instance is held across the call.
        unsafe {
            callback(
                environment,
                time,
                TRUE,
                FALSE,
                FALSE,
                FALSE,
                &mut early,
                &mut early_time,
            )
        };
        // SAFETY: as above; the callback has returned.
        unsafe { (*component).instance.intermediate = None };
    }
    true
}

/// fmi3EnterStepMode: only for FMUs with event mode, which this is not.
pub unsafe fn enter_step_mode<M: Model>(c: Fmi3Instance) -> Fmi3Status {
    // SAFETY: this module's contract.
    unsafe { unsupported::<M>(c, "fmi3EnterStepMode") }
}

/// A function of the FMI 3.0 interface the kit does not support (other variable
/// types, clocks, event mode, configuration mode, directional and adjoint
/// derivatives, dependency queries): fmi3Error with a message naming it.
pub unsafe fn unsupported<M: Model>(c: Fmi3Instance, function: &'static str) -> Fmi3Status {
    if c.is_null() {
        return ERROR;
    }
    // SAFETY: this module's contract.
    unsafe {
        with_instance::<M>(c, Call::Unsupported(function), |_| {
            Err(Failure::usage(
                "not supported by this FMU (the kit supports Float64, Int32 and Boolean variables, no event mode, clocks or derivatives)",
            ))
        })
    }
}

#[cfg(test)]
mod tests {
    //! The FMI 3.0 layer called as an importer calls it, on the kit's test model
    //! (ẋ = u − k·x; value references k 0, x0 1, tolerance 2, u 3, y 4, z 5, x 6,
    //! der(x) 7, time 8).

    use std::ffi::CString;
    use std::ptr;
    use std::sync::Mutex;

    use super::*;
    use crate::ffi::{free_instance, get_fmu_state, set_fmu_state};
    use crate::tests::Decay;

    type D = Decay;
    const OK: Fmi3Status = 0;
    const DISCARD_OR_WORSE: Fmi3Status = 2;

    static MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());

    unsafe extern "C" fn log(_: *mut c_void, _: Fmi3Status, _: Fmi3String, message: Fmi3String) {
        // SAFETY: the kit passes a NUL-terminated message.
        let text = unsafe { CStr::from_ptr(message) }
            .to_string_lossy()
            .into_owned();
        MESSAGES.lock().unwrap().push(text);
    }

    fn instantiate(token: &str) -> Fmi3Instance {
        let name = CString::new("decay3").unwrap();
        let token = CString::new(token).unwrap();
        // SAFETY: valid NUL-terminated strings.
        unsafe {
            instantiate_co_simulation::<D>(
                name.as_ptr(),
                token.as_ptr(),
                0,
                ptr::null_mut(),
                Some(log),
                None,
            )
        }
    }

    fn get(c: Fmi3Instance, vr: u32) -> f64 {
        let mut v = [f64::NAN];
        // SAFETY: one value reference, one value.
        assert_eq!(
            unsafe { get_float64::<D>(c, &vr, 1, v.as_mut_ptr(), 1) },
            OK
        );
        v[0]
    }

    #[test]
    fn the_fmi3_layer_steps_the_model_as_the_fmi2_layer_does() {
        assert!(instantiate("{not-the-token}").is_null());
        let c = instantiate(xml::model_guid::<D>());
        assert!(!c.is_null());
        let (mut event, mut terminate, mut early, mut last) = (1u8, 1u8, 1u8, f64::NAN);
        // SAFETY: c is a live instance of D; every array holds what the call says.
        unsafe {
            let k = [2.0];
            assert_eq!(set_float64::<D>(c, &0, 1, k.as_ptr(), 1), OK);
            assert_eq!(enter_initialization_mode::<D>(c, 0, 0.0, 0.5, 0, 0.0), OK);
            assert_eq!(crate::ffi::exit_initialization_mode::<D>(c), OK);
            assert_eq!(get(c, 8), 0.5, "time starts at the start time");
            let u = [1.0];
            assert_eq!(set_float64::<D>(c, &3, 1, u.as_ptr(), 1), OK);
            let status = do_step::<D>(
                c,
                0.5,
                0.25,
                &mut event,
                &mut terminate,
                &mut early,
                &mut last,
            );
            assert_eq!(status, OK);
            assert_eq!((event, terminate, early, last), (0, 0, 0, 0.75));
        }
        // x(t) = 1/2 + (x0 − 1/2)·e^(−k (t − t0)) with x0 = 1, k = 2, u = 1.
        let x = get(c, 6);
        let exact = 0.5 + 0.5 * (-2.0 * 0.25f64).exp();
        assert!((x - exact).abs() < 1e-9, "x = {x}, exact {exact}");
        assert_eq!(get(c, 4), x + 1.0, "y = x + u");
        assert_eq!(get(c, 8), 0.75);
        // SAFETY: as above; the state is freed with the instance's state functions.
        unsafe {
            let mut state: *mut c_void = ptr::null_mut();
            assert_eq!(get_fmu_state::<D>(c, &mut state), OK);
            do_step::<D>(
                c,
                0.75,
                0.25,
                &mut event,
                &mut terminate,
                &mut early,
                &mut last,
            );
            let after = get(c, 6);
            assert_eq!(set_fmu_state::<D>(c, state), OK);
            assert_eq!(get(c, 6), x);
            do_step::<D>(
                c,
                0.75,
                0.25,
                &mut event,
                &mut terminate,
                &mut early,
                &mut last,
            );
            assert_eq!(
                get(c, 6).to_bits(),
                after.to_bits(),
                "a restored step repeats bit for bit"
            );
            crate::ffi::free_fmu_state::<D>(c, &mut state);
            free_instance::<D>(c);
        }
    }

    /// One callback: its time, `intermediateVariableSetRequested`,
    /// `intermediateVariableGetAllowed`, `intermediateStepFinished`, and the status
    /// of the set made in it.
    type Call = (f64, u8, u8, u8, Fmi3Status);

    /// The instance environment of [`intermediate_update`]: the instance and the
    /// callbacks made.
    struct Environment {
        c: std::cell::Cell<Fmi3Instance>,
        calls: std::cell::RefCell<Vec<Call>>,
    }

    /// u(t) = 0.5 + 2 (t − 0.5) − (t − 0.5)²/2, set at every intermediate time.
    unsafe extern "C" fn intermediate_update(
        env: *mut c_void,
        time: f64,
        set_requested: Fmi3Boolean,
        get_allowed: Fmi3Boolean,
        finished: Fmi3Boolean,
        _can_return_early: Fmi3Boolean,
        _early_return_requested: *mut Fmi3Boolean,
        _early_return_time: *mut f64,
    ) {
        // SAFETY: the environment is the test's `Environment`, alive for the call.
        let env = unsafe { &*env.cast_const().cast::<Environment>() };
        let s = time - 0.5;
        let u = [0.5 + s * (2.0 - 0.5 * s)];
        // SAFETY: the instance that is calling back; one value reference, one value.
        let status = unsafe { set_float64::<D>(env.c.get(), &3, 1, u.as_ptr(), 1) };
        env.calls
            .borrow_mut()
            .push((time, set_requested, get_allowed, finished, status));
    }

    /// The FMI 3.0 build asks for its inputs at t + h/2 and t + h and steps with the
    /// quadratic through them: the FMI 2.0 build's step with the same polynomial as
    /// input derivatives, to rounding.
    #[test]
    fn inputs_set_in_intermediate_update_are_the_steps_polynomial() {
        let env = Box::new(Environment {
            c: std::cell::Cell::new(ptr::null_mut()),
            calls: Default::default(),
        });
        let name = CString::new("decay3").unwrap();
        let token = CString::new(xml::model_guid::<D>()).unwrap();
        let env_ptr: *const Environment = &*env;
        // SAFETY: valid NUL-terminated strings; the environment outlives the instance.
        let c = unsafe {
            instantiate_co_simulation::<D>(
                name.as_ptr(),
                token.as_ptr(),
                0,
                env_ptr.cast_mut().cast(),
                Some(log),
                Some(intermediate_update),
            )
        };
        assert!(!c.is_null());
        env.c.set(c);
        let (mut event, mut terminate, mut early, mut last) = (1u8, 1u8, 1u8, f64::NAN);
        // SAFETY: c is a live instance of D; every array holds what the call says.
        unsafe {
            let parameters = [1.0, 1.0, 1e-10];
            assert_eq!(
                set_float64::<D>(c, [0, 1, 2].as_ptr(), 3, parameters.as_ptr(), 3),
                OK
            );
            assert_eq!(enter_initialization_mode::<D>(c, 0, 0.0, 0.5, 0, 0.0), OK);
            assert_eq!(crate::ffi::exit_initialization_mode::<D>(c), OK);
            assert_eq!(set_float64::<D>(c, &3, 1, [0.5].as_ptr(), 1), OK);
            let status = do_step::<D>(
                c,
                0.5,
                0.25,
                &mut event,
                &mut terminate,
                &mut early,
                &mut last,
            );
            assert_eq!(status, OK);
        }
        let calls = env.calls.borrow().clone();
        assert_eq!(
            calls,
            [(0.625, 1, 0, 0, OK), (0.75, 1, 0, 0, OK)],
            "asked at t + h/2 and t + h, sets only"
        );
        let x = get(c, 6);
        let model = D::new(&crate::Parameters::new(
            &D::DECLARATION,
            &[1.0, 1.0],
            &[],
            &[],
        ))
        .unwrap();
        let jets = [crate::InputJet {
            value: 0.5,
            d1: 2.0,
            d2: -1.0,
        }];
        let mut expected = [1.0];
        crate::integrate::step(&model, 0.5, 0.25, &mut expected, &jets, 1e-10).unwrap();
        assert!(
            (x - expected[0]).abs() <= 1e-13 * expected[0].abs(),
            "x = {x}, with input derivatives {}",
            expected[0]
        );
        // The input after the step is the polynomial's value at t + h.
        let u_end = 0.5 + 0.25 * (2.0 - 0.5 * 0.25);
        assert!((get(c, 3) - u_end).abs() < 1e-14, "u = {}", get(c, 3));
        // SAFETY: c is live; freed once.
        unsafe { free_instance::<D>(c) };
    }

    /// Decay, logging two messages of its own in every step: one through
    /// [`EnvironmentLogger::log`], one with a printf format as a C FMU logs.
    struct Talker(Decay);

    impl Model for Talker {
        const DECLARATION: crate::Declaration = Decay::DECLARATION;
        const LOGS: bool = true;
        fn new(p: &crate::Parameters) -> Result<Self, String> {
            Decay::new(p).map(Talker)
        }
        fn initial_states(&self, x: &mut [f64]) {
            self.0.initial_states(x)
        }
        fn derivatives(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
            self.0.derivatives(t, x, u, dx)
        }
        fn outputs(&self, t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
            self.0.outputs(t, x, u, y)
        }
        fn exact_step(&self, t: f64, _h: f64, _x: &mut [f64], _u: &[crate::InputJet]) -> bool {
            if let Some(logger) = crate::environment_logger() {
                logger.log(
                    Status::Warning,
                    "logStatusWarning",
                    "the talker's own message",
                );
                // SAFETY: the hook's logger, environment and name, during the call;
                // "%d at t = %g" matches the int and the double passed.
                unsafe {
                    (logger.logger)(
                        logger.component_environment,
                        logger.instance_name,
                        1,
                        c"logStatusWarning".as_ptr(),
                        c"formatted %d at t = %g".as_ptr(),
                        42 as std::ffi::c_int,
                        t,
                    )
                };
            }
            false
        }
    }

    /// A model's own messages reach the importer's fmi3LogMessageCallback, formatted.
    #[test]
    fn the_models_own_messages_reach_the_fmi3_log_callback() {
        let name = CString::new("talker").unwrap();
        let token = CString::new(xml::model_guid::<Talker>()).unwrap();
        let (mut event, mut terminate, mut early, mut last) = (0u8, 0u8, 0u8, 0.0);
        // SAFETY: valid NUL-terminated strings; c is a live instance while used.
        unsafe {
            let c = instantiate_co_simulation::<Talker>(
                name.as_ptr(),
                token.as_ptr(),
                0,
                ptr::null_mut(),
                Some(log),
                None,
            );
            assert!(!c.is_null());
            assert_eq!(
                enter_initialization_mode::<Talker>(c, 0, 0.0, 0.0, 0, 0.0),
                OK
            );
            assert_eq!(crate::ffi::exit_initialization_mode::<Talker>(c), OK);
            let status = do_step::<Talker>(
                c,
                0.0,
                0.5,
                &mut event,
                &mut terminate,
                &mut early,
                &mut last,
            );
            assert_eq!(status, OK);
            free_instance::<Talker>(c);
        }
        let messages = MESSAGES.lock().unwrap().join("\n");
        for expected in ["the talker's own message", "formatted 42 at t = 0"] {
            assert!(
                messages.contains(expected),
                "{expected:?} not in\n{messages}"
            );
        }
    }

    #[test]
    fn bad_fmi3_calls_return_error_with_a_message_naming_the_fmi3_function() {
        let c = instantiate(xml::model_guid::<D>());
        let v = [0.0; 2];
        // SAFETY: c is a live instance of D; every array holds what the call says
        // (nValues = 2 for one value reference is refused before the arrays are read).
        unsafe {
            assert!(set_float64::<D>(c, &0, 1, v.as_ptr(), 2) >= DISCARD_OR_WORSE);
            assert!(
                set_float64::<D>(c, &8, 1, v.as_ptr(), 1) >= DISCARD_OR_WORSE,
                "time is read-only"
            );
            assert!(unsupported::<D>(c, "fmi3GetFloat32") >= DISCARD_OR_WORSE);
            assert!(enter_step_mode::<D>(c) >= DISCARD_OR_WORSE);
            free_instance::<D>(c);
        }
        let messages = MESSAGES.lock().unwrap().join("\n");
        for expected in [
            "fmi3SetFloat64: nValues is 2, expected 1",
            "fmi3SetFloat64: time (value reference 8) cannot be set",
            "fmi3GetFloat32: not supported",
            "fmi3EnterStepMode: not supported",
        ] {
            assert!(
                messages.contains(expected),
                "{expected:?} not in\n{messages}"
            );
        }
    }

    #[test]
    fn the_fmi3_model_description_keeps_the_value_references_and_adds_time() {
        let text = xml::model_description_fmi3(&D::DECLARATION).unwrap();
        for expected in [
            r#"fmiVersion="3.0""#,
            &format!(r#"instantiationToken="{}""#, xml::guid(&D::DECLARATION)),
            r#"<Float64 name="u" valueReference="3" causality="input" variability="continuous" intermediateUpdate="true" start="0.0"/>"#,
            r#"<Float64 name="der(x)" valueReference="7" description="Derivative of x" causality="local" variability="continuous" initial="calculated" derivative="6"/>"#,
            r#"<Float64 name="time" valueReference="8" description="Simulation time" causality="independent" variability="continuous"/>"#,
            r#"<Output valueReference="4" dependencies="3 6"/>"#,
            r#"<Output valueReference="5" dependencies="6"/>"#,
            r#"<InitialUnknown valueReference="4"/>"#,
            r#"canGetAndSetFMUState="true" canSerializeFMUState="true""#,
            r#"canHandleVariableCommunicationStepSize="true" maxOutputDerivativeOrder="1" providesIntermediateUpdate="true""#,
        ] {
            assert!(text.contains(expected), "{expected}\nnot in\n{text}");
        }
    }
}
