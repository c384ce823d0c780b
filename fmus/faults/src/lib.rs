//! `faults`: the oscillator FMU (same variables, same results in mode 0) that
//! misbehaves inside `fmi2DoStep` on demand, so that Tether's handling of FMUs
//! that crash, exit, hang or flood the log can be tested on a real FMU in a real
//! process (docs/reliability.md).
//!
//! The integer parameter `mode` selects the fault, struck in the first
//! `fmi2DoStep` whose communication point is at least `at` (default 0.5 s) and,
//! for the lasting faults, in every one after it:
//!
//! | mode | fault |
//! |---|---|
//! | 0 | none: the oscillator |
//! | 1 | segmentation fault (a write to an unmapped address) |
//! | 2 | `abort()` |
//! | 3 | `exit(0)` |
//! | 4 | `exit(3)` |
//! | 5 | an endless loop (busy) |
//! | 6 | a log flood: `flood` warnings per `fmi2DoStep` (default 2000) |
//! | 7 | slow calls: each `fmi2DoStep` sleeps `pause` seconds (default 1) |
//!
//! `delay` (seconds, default 0) makes every `fmi2DoStep` sleep, in every mode, to
//! slow a run down to wall-clock scales.
//!
//! The kit's [`export_fmu!`](tether_fmu_kit::export_fmu) does not give a model the
//! environment's logger, so this crate writes the exports itself (the kit's, with
//! `fmi2Instantiate` remembering the logger and `fmi2DoStep` putting it in scope
//! for the model).

use std::cell::Cell;
use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::sync::Mutex;

use tether_fmu_kit::ffi::{Fmi2CallbackFunctions, Fmi2CallbackLogger, Fmi2Component};

mod fault;
mod model;

pub use fault::Mode;
pub use model::Faults;

/// The environment's logger of each live instance: component address, logger,
/// component environment, instance name.
struct Logger {
    component: usize,
    logger: Fmi2CallbackLogger,
    env: usize,
    name: CString,
}

static LOGGERS: Mutex<Vec<Logger>> = Mutex::new(Vec::new());

thread_local! {
    /// The logger of the instance whose `fmi2DoStep` runs on this thread.
    static IN_SCOPE: Cell<Option<(Fmi2CallbackLogger, usize, *const c_char)>> = const { Cell::new(None) };
}

fn loggers() -> std::sync::MutexGuard<'static, Vec<Logger>> {
    LOGGERS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Remembers the logger for `c`.
///
/// # Safety
/// `name` is a NUL-terminated string and `functions` points at valid callbacks.
unsafe fn remember_logger(
    c: Fmi2Component,
    name: *const c_char,
    functions: *const Fmi2CallbackFunctions,
) {
    // SAFETY: the caller's contract.
    let (name, callbacks) = unsafe { (CStr::from_ptr(name).to_owned(), &*functions) };
    loggers().push(Logger {
        component: c as usize,
        logger: callbacks.logger,
        env: callbacks.component_environment as usize,
        name,
    });
}

fn forget_logger(c: Fmi2Component) {
    loggers().retain(|l| l.component != c as usize);
}

/// Puts the logger of an instance in scope for the duration of one call.
struct LoggerInScope;

impl LoggerInScope {
    fn enter(c: Fmi2Component) -> LoggerInScope {
        let found = loggers()
            .iter()
            .find(|l| l.component == c as usize)
            .map(|l| (l.logger, l.env, l.name.as_ptr()));
        IN_SCOPE.set(found);
        LoggerInScope
    }
}

impl Drop for LoggerInScope {
    fn drop(&mut self) {
        IN_SCOPE.set(None);
    }
}

/// One warning through the environment's logger, formatted by the environment
/// (`%u`, `%g`), as a C FMU logs.
fn log_warning(n: u32, t: f64) {
    let Some((Some(logger), env, name)) = IN_SCOPE.get() else {
        return;
    };
    // SAFETY: the logger and its environment were given to fmi2Instantiate for the
    // instance whose fmi2DoStep is running (the FMI contract keeps them valid until
    // fmi2FreeInstance); `name` lives in LOGGERS until then; the format's two
    // conversions match the unsigned int and the double passed.
    unsafe {
        logger(
            env as *mut c_void,
            name,
            1 as c_int,
            c"logStatusWarning".as_ptr(),
            c"flood message %u at t = %g".as_ptr(),
            n as std::ffi::c_uint,
            t,
        );
    }
}

/// A segmentation fault, as a buggy FMU has one: a write to an unmapped address.
fn crash() -> ! {
    let address = std::ptr::without_provenance_mut::<u64>(64);
    // SAFETY: none: this write is the fault the `segfault` mode asks for. The page
    // at address 64 is never mapped on Linux (mmap_min_addr), so the process gets
    // SIGSEGV; the volatile write keeps the compiler from reasoning about it.
    unsafe { address.write_volatile(0xdead) };
    std::process::abort()
}

#[allow(non_snake_case, clippy::missing_safety_doc)]
mod exports {
    use super::*;
    use std::ffi::{c_char, c_int};
    use tether_fmu_kit::ffi as k;
    use tether_fmu_kit::ffi::{
        Fmi2Boolean as B, Fmi2Component as C, Fmi2FmuState as S, Fmi2Status as St,
        Fmi2String as Str, Fmi2ValueReference as Vr,
    };
    type M = Faults;

    /// The generated modelDescription.xml (NUL-terminated, static), or null if
    /// the declaration is invalid.
    #[unsafe(no_mangle)]
    pub extern "C" fn tether_fmu_kit_model_description() -> *const c_char {
        static XML: std::sync::OnceLock<Option<std::ffi::CString>> = std::sync::OnceLock::new();
        k::model_description::<M>(&XML)
    }

    #[unsafe(no_mangle)]
    pub extern "C" fn fmi2GetTypesPlatform() -> *const c_char {
        k::get_types_platform()
    }
    #[unsafe(no_mangle)]
    pub extern "C" fn fmi2GetVersion() -> *const c_char {
        k::get_version()
    }

    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2SetDebugLogging(
        c: C,
        on: B,
        n: usize,
        categories: *const Str,
    ) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::set_debug_logging::<M>(c, on, n, categories) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2Instantiate(
        name: Str,
        fmu_type: c_int,
        guid: Str,
        _resources: Str,
        functions: *const k::Fmi2CallbackFunctions,
        _visible: B,
        logging_on: B,
    ) -> C {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        let c = unsafe { k::instantiate::<M>(name, fmu_type, guid, functions, logging_on) };
        if !c.is_null() {
            // SAFETY: the kit accepted the instance, so `functions` and `name` are valid.
            unsafe { crate::remember_logger(c, name, functions) };
        }
        c
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2FreeInstance(c: C) {
        crate::forget_logger(c);
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::free_instance::<M>(c) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2SetupExperiment(
        c: C,
        tol_defined: B,
        tol: f64,
        start: f64,
        stop_defined: B,
        stop: f64,
    ) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::setup_experiment::<M>(c, tol_defined, tol, start, stop_defined, stop) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2EnterInitializationMode(c: C) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::enter_initialization_mode::<M>(c) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2ExitInitializationMode(c: C) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::exit_initialization_mode::<M>(c) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2Terminate(c: C) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::terminate::<M>(c) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2Reset(c: C) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::reset::<M>(c) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetReal(c: C, vr: *const Vr, n: usize, v: *mut f64) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_real::<M>(c, vr, n, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetInteger(c: C, vr: *const Vr, n: usize, v: *mut c_int) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_integer::<M>(c, vr, n, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetBoolean(c: C, vr: *const Vr, n: usize, v: *mut B) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_boolean::<M>(c, vr, n, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetString(c: C, vr: *const Vr, n: usize, v: *mut Str) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_string::<M>(c, vr, n, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2SetReal(c: C, vr: *const Vr, n: usize, v: *const f64) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::set_real::<M>(c, vr, n, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2SetInteger(c: C, vr: *const Vr, n: usize, v: *const c_int) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::set_integer::<M>(c, vr, n, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2SetBoolean(c: C, vr: *const Vr, n: usize, v: *const B) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::set_boolean::<M>(c, vr, n, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2SetString(c: C, vr: *const Vr, n: usize, v: *const Str) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::set_string::<M>(c, vr, n, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetFMUstate(c: C, s: *mut S) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_fmu_state::<M>(c, s) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2SetFMUstate(c: C, s: S) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::set_fmu_state::<M>(c, s) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2FreeFMUstate(c: C, s: *mut S) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::free_fmu_state::<M>(c, s) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2SerializedFMUstateSize(c: C, s: S, size: *mut usize) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::serialized_fmu_state_size::<M>(c, s, size) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2SerializeFMUstate(
        c: C,
        s: S,
        bytes: *mut c_char,
        size: usize,
    ) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::serialize_fmu_state::<M>(c, s, bytes, size) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2DeSerializeFMUstate(
        c: C,
        bytes: *const c_char,
        size: usize,
        s: *mut S,
    ) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::deserialize_fmu_state::<M>(c, bytes, size, s) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetDirectionalDerivative(
        c: C,
        _u: *const Vr,
        _nu: usize,
        _z: *const Vr,
        _nz: usize,
        _dz: *const f64,
        _du: *mut f64,
    ) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_directional_derivative::<M>(c) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2SetRealInputDerivatives(
        c: C,
        vr: *const Vr,
        n: usize,
        order: *const c_int,
        v: *const f64,
    ) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::set_real_input_derivatives::<M>(c, vr, n, order, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetRealOutputDerivatives(
        c: C,
        vr: *const Vr,
        n: usize,
        order: *const c_int,
        v: *mut f64,
    ) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_real_output_derivatives::<M>(c, vr, n, order, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2DoStep(c: C, t: f64, h: f64, no_prior: B) -> St {
        let _logger = crate::LoggerInScope::enter(c);
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::do_step::<M>(c, t, h, no_prior) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2CancelStep(c: C) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::cancel_step::<M>(c) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetStatus(c: C, kind: c_int, v: *mut St) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_status::<M>(c, kind, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetRealStatus(c: C, kind: c_int, v: *mut f64) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_real_status::<M>(c, kind, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetIntegerStatus(c: C, kind: c_int, v: *mut c_int) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_integer_status::<M>(c, kind, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetBooleanStatus(c: C, kind: c_int, v: *mut B) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_boolean_status::<M>(c, kind, v) }
    }
    #[unsafe(no_mangle)]
    pub unsafe extern "C" fn fmi2GetStringStatus(c: C, kind: c_int, v: *mut Str) -> St {
        // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
        unsafe { k::get_string_status::<M>(c, kind, v) }
    }
}
