//! The C side: fmi2 types and one generic function per fmi2 function, called by the
//! `#[no_mangle]` wrappers that [`crate::export_fmu!`] generates. This is the only
//! module with `unsafe`. Every function checks its pointers, never lets a panic
//! unwind into C (a panic becomes fmi2Fatal) and delegates to [`Instance`].

use std::cell::Cell;
use std::ffi::{c_char, c_int, c_uint, c_void, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::ptr;
use std::sync::OnceLock;

use crate::instance::{Failure, Instance, LogFn, Outcome, Status};
use crate::machine::Call;
use crate::model::Model;
use crate::xml;

pub type Fmi2Component = *mut c_void;
pub type Fmi2FmuState = *mut c_void;
pub type Fmi2Status = c_int;
pub type Fmi2Boolean = c_int;
pub type Fmi2ValueReference = c_uint;
pub type Fmi2String = *const c_char;

const FMI2_TRUE: Fmi2Boolean = 1;
const FMI2_MODEL_EXCHANGE: c_int = 0;
const FMI2_COSIMULATION: c_int = 1;

/// fmi2CallbackLogger: a C variadic function; the kit always passes "%s" and one
/// NUL-terminated message.
pub type Fmi2CallbackLogger =
    Option<unsafe extern "C" fn(*mut c_void, Fmi2String, Fmi2Status, Fmi2String, Fmi2String, ...)>;

/// fmi2CallbackFunctions. The memory functions are not used: the kit allocates with
/// Rust's allocator (allowed: they are only a service offered by the environment).
#[repr(C)]
pub struct Fmi2CallbackFunctions {
    pub logger: Fmi2CallbackLogger,
    pub allocate_memory: Option<unsafe extern "C" fn(usize, usize) -> *mut c_void>,
    pub free_memory: Option<unsafe extern "C" fn(*mut c_void)>,
    pub step_finished: Option<unsafe extern "C" fn(*mut c_void, Fmi2Status)>,
    pub component_environment: *mut c_void,
}

/// The environment's logger of one instance, as given to `fmi2Instantiate`: the
/// hook through which a model logs messages of its own ([`environment_logger`]).
#[derive(Clone, Copy)]
pub struct EnvironmentLogger {
    /// The `fmi2CallbackLogger` (C-variadic: `message` is a printf format whose
    /// conversions the arguments after it fill).
    pub logger:
        unsafe extern "C" fn(*mut c_void, Fmi2String, Fmi2Status, Fmi2String, Fmi2String, ...),
    /// The `componentEnvironment`, the logger's first argument.
    pub component_environment: *mut c_void,
    /// The instance name (NUL-terminated), the logger's second argument.
    pub instance_name: Fmi2String,
}

impl EnvironmentLogger {
    /// Logs `message` as it is (passed as the argument of a `"%s"` format, as the
    /// kit's own messages are) with `status` and `category` (one of the categories
    /// of the model description, e.g. `logStatusWarning`). Unlike the kit's own
    /// messages it is sent whatever `fmi2SetDebugLogging` enabled: the model
    /// decides.
    pub fn log(&self, status: Status, category: &str, message: &str) {
        let category = c_string(category);
        let message = c_string(message);
        // SAFETY: the logger, its environment and the instance name are those
        // fmi2Instantiate received, valid until fmi2FreeInstance (the FMI contract;
        // the kit hands them out only during a call on the instance); the strings
        // are NUL-terminated and live across the call; "%s" consumes exactly the one
        // extra argument passed.
        unsafe {
            (self.logger)(
                self.component_environment,
                self.instance_name,
                status as Fmi2Status,
                category.as_ptr(),
                c"%s".as_ptr(),
                message.as_ptr(),
            );
        }
    }
}

thread_local! {
    /// The logger of the instance whose FMI call runs on this thread, if it has one.
    static IN_CALL: Cell<Option<EnvironmentLogger>> = const { Cell::new(None) };
}

/// The environment's logger of the instance whose FMI call (`fmi2DoStep`,
/// `fmi2GetReal`, …) is running on this thread, for a model's own messages; `None`
/// outside calls, when the environment gave no logger and when the model does not
/// declare [`Model::LOGS`]. Valid for the duration of the call only: a model must
/// not keep it.
pub fn environment_logger() -> Option<EnvironmentLogger> {
    IN_CALL.get()
}

/// Puts an instance's logger in scope for one call; the previous one comes back on
/// drop (also after a panic).
struct LoggerScope(Option<EnvironmentLogger>);

impl LoggerScope {
    fn enter(logger: Option<EnvironmentLogger>) -> LoggerScope {
        LoggerScope(IN_CALL.replace(logger))
    }
}

impl Drop for LoggerScope {
    fn drop(&mut self) {
        IN_CALL.set(self.0);
    }
}

/// What a component pointer points at: the instance and its environment's logger.
struct Component<M: Model> {
    instance: Instance<M>,
    logger: Option<EnvironmentLogger>,
    /// FMI 3.0: the importer's intermediate update callback and its instance
    /// environment, when given.
    intermediate_update: Option<(fmi3::IntermediateUpdate, *mut c_void)>,
    /// FMI 3.0: what `logger.component_environment` points at.
    _fmi3_log: Option<Box<fmi3::Fmi3LogEnv>>,
    /// The instance name `logger.instance_name` points into.
    _name: CString,
}

pub(crate) const ERROR: Fmi2Status = Status::Error as Fmi2Status;
const FATAL: Fmi2Status = Status::Fatal as Fmi2Status;

/// Borrows `n` items at `p`; `None` if `p` is null while `n > 0`.
///
/// # Safety
/// A non-null `p` must point at `n` valid, initialized items that outlive the borrow.
pub unsafe fn slice<'a, T>(p: *const T, n: usize) -> Option<&'a [T]> {
    match (p.is_null(), n) {
        (_, 0) => Some(&[]),
        (true, _) => None,
        // SAFETY: p is non-null and the caller guarantees n valid items.
        (false, _) => Some(unsafe { std::slice::from_raw_parts(p, n) }),
    }
}

/// Mutable version of [`slice`].
///
/// # Safety
/// As [`slice`], and the items must not be aliased during the borrow.
pub unsafe fn slice_mut<'a, T>(p: *mut T, n: usize) -> Option<&'a mut [T]> {
    match (p.is_null(), n) {
        (_, 0) => Some(&mut []),
        (true, _) => None,
        // SAFETY: p is non-null and the caller guarantees n valid, unaliased items.
        (false, _) => Some(unsafe { std::slice::from_raw_parts_mut(p, n) }),
    }
}

/// The failure of a call given a null pointer for `what`.
pub fn null(what: &str) -> Failure {
    Failure::usage(format!("{what} is a null pointer"))
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    let text = payload.downcast_ref::<&str>().map(|s| s.to_string());
    text.or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

/// Runs `f` on the instance behind `c` through the state-machine check; a panic
/// becomes fmi2Fatal.
///
/// # Safety
/// `c` must be null or a pointer returned by [`instantiate`] for the same `M` and not
/// yet freed.
///
/// Inlined into each entry point, as are the value and step functions it runs: the
/// FMI 2.0 and 3.0 layers share them, and a call out of line is a measurable part of
/// a cheap FMU's step (callgrind, docs/performance.md "Profiling").
#[inline(always)]
unsafe fn with_instance<M: Model>(
    c: Fmi2Component,
    call: Call,
    f: impl FnOnce(&mut Instance<M>) -> Outcome,
) -> Fmi2Status {
    if c.is_null() {
        return ERROR;
    }
    // SAFETY: per this function's contract, c is a live Box<Component<M>> from
    // instantiate.
    let component = unsafe { &mut *c.cast::<Component<M>>() };
    let _logger = M::LOGS.then(|| LoggerScope::enter(component.logger));
    let instance = &mut component.instance;
    match catch_unwind(AssertUnwindSafe(|| instance.call(call, f))) {
        Ok(status) => status as Fmi2Status,
        Err(payload) => {
            let failure = Failure {
                status: Status::Fatal,
                message: format!("panic: {}", panic_message(payload.as_ref())),
                enters_error_state: true,
            };
            let _ = catch_unwind(AssertUnwindSafe(|| instance.fail(call, failure)));
            FATAL
        }
    }
}

/// Whether the instance behind `c` was made by the FMI 3.0 layer.
///
/// # Safety
/// `c` must be a (non-null) pointer returned by this library's instantiate
/// functions for the same `M` and not yet freed.
unsafe fn is_fmi3<M: Model>(c: Fmi2Component) -> bool {
    // SAFETY: per this function's contract, c is a live Box<Component<M>>; only a
    // flag is read.
    unsafe { &*c.cast::<Component<M>>() }.instance.fmi3
}

fn c_string(text: &str) -> CString {
    CString::new(text.replace('\0', " ")).unwrap_or_default()
}

fn make_logger(callbacks: &Fmi2CallbackFunctions, name: &str) -> Option<LogFn> {
    let logger = callbacks.logger?;
    let env = callbacks.component_environment;
    let name = c_string(name);
    Some(Box::new(
        move |status: Status, category: &str, message: &str| {
            let category = c_string(category);
            let message = c_string(message);
            // SAFETY: the environment promised a valid logger for the instance's lifetime;
            // all strings are NUL-terminated and live across the call; "%s" consumes
            // exactly the one extra argument passed.
            unsafe {
                logger(
                    env,
                    name.as_ptr(),
                    status as Fmi2Status,
                    category.as_ptr(),
                    c"%s".as_ptr(),
                    message.as_ptr(),
                );
            }
        },
    ))
}

/// The generated modelDescription.xml, kept for the life of the library.
pub fn model_description<M: Model>(cache: &'static OnceLock<Option<CString>>) -> *const c_char {
    let make = || match xml::model_description(&M::DECLARATION) {
        Ok(text) => CString::new(text).ok(),
        Err(e) => {
            eprintln!(
                "tether-fmu-kit: invalid declaration of {}: {e}",
                M::DECLARATION.model_identifier
            );
            None
        }
    };
    match catch_unwind(AssertUnwindSafe(|| cache.get_or_init(make))) {
        Ok(Some(text)) => text.as_ptr(),
        _ => ptr::null(),
    }
}

/// The generated FMI 3.0 modelDescription.xml, kept for the life of the library.
pub fn model_description_fmi3<M: Model>(
    cache: &'static OnceLock<Option<CString>>,
) -> *const c_char {
    let make = || match xml::model_description_fmi3(&M::DECLARATION) {
        Ok(text) => CString::new(text).ok(),
        Err(e) => {
            eprintln!(
                "tether-fmu-kit: invalid declaration of {}: {e}",
                M::DECLARATION.model_identifier
            );
            None
        }
    };
    match catch_unwind(AssertUnwindSafe(|| cache.get_or_init(make))) {
        Ok(Some(text)) => text.as_ptr(),
        _ => ptr::null(),
    }
}

pub fn get_types_platform() -> *const c_char {
    c"default".as_ptr()
}

pub fn get_version() -> *const c_char {
    c"2.0".as_ptr()
}

/// fmi2Instantiate: null on any invalid argument (logged if a logger was given).
///
/// # Safety
/// Non-null string arguments must be NUL-terminated; a non-null `functions` must point
/// at a valid fmi2CallbackFunctions.
pub unsafe fn instantiate<M: Model>(
    instance_name: Fmi2String,
    fmu_type: c_int,
    fmu_guid: Fmi2String,
    functions: *const Fmi2CallbackFunctions,
    logging_on: Fmi2Boolean,
) -> Fmi2Component {
    let result = catch_unwind(|| {
        if instance_name.is_null() || functions.is_null() {
            return ptr::null_mut();
        }
        // SAFETY: non-null, and the caller guarantees a NUL-terminated string.
        let name = unsafe { CStr::from_ptr(instance_name) }
            .to_string_lossy()
            .into_owned();
        // SAFETY: non-null, and the caller guarantees a valid callback struct.
        let callbacks = unsafe { &*functions };
        let instance = Instance::<M>::new(
            &name,
            make_logger(callbacks, &name),
            logging_on == FMI2_TRUE,
        );
        let expected = xml::model_guid::<M>();
        let guid = if fmu_guid.is_null() {
            None
        } else {
            // SAFETY: non-null, and the caller guarantees a NUL-terminated string.
            Some(
                unsafe { CStr::from_ptr(fmu_guid) }
                    .to_string_lossy()
                    .into_owned(),
            )
        };
        let me = M::DECLARATION.model_exchange && fmu_type == FMI2_MODEL_EXCHANGE;
        let mut instance = instance;
        instance.me = me;
        let problem = if fmu_type != FMI2_COSIMULATION && !me {
            Some(if M::DECLARATION.model_exchange {
                format!("fmuType {fmu_type} is neither fmi2ModelExchange nor fmi2CoSimulation")
            } else {
                "this FMU supports co-simulation only (fmuType must be fmi2CoSimulation)"
                    .to_string()
            })
        } else if guid.as_deref() != Some(expected) {
            Some(format!(
                "GUID {guid:?} does not match the model's GUID {expected}"
            ))
        } else {
            None
        };
        if let Some(problem) = problem {
            instance.log(Status::Error, &format!("fmi2Instantiate: {problem}"));
            return ptr::null_mut();
        }
        let name = c_string(&name);
        let logger = callbacks.logger.map(|logger| EnvironmentLogger {
            logger,
            component_environment: callbacks.component_environment,
            instance_name: name.as_ptr(),
        });
        let component = Component {
            instance,
            logger,
            intermediate_update: None,
            _fmi3_log: None,
            _name: name,
        };
        Box::into_raw(Box::new(component)).cast::<c_void>()
    });
    result.unwrap_or(ptr::null_mut())
}

/// # Safety
/// `c` must be null or a live instance of `M`; it is invalid afterwards.
pub unsafe fn free_instance<M: Model>(c: Fmi2Component) {
    if !c.is_null() {
        // SAFETY: c came from Box::into_raw in instantiate::<M> and is freed only here.
        let component = unsafe { Box::from_raw(c.cast::<Component<M>>()) };
        let _ = catch_unwind(AssertUnwindSafe(|| drop(component)));
    }
}

/// # Safety
/// See [`with_instance`]; `categories` must hold `n` NUL-terminated strings.
pub unsafe fn set_debug_logging<M: Model>(
    c: Fmi2Component,
    on: Fmi2Boolean,
    n: usize,
    categories: *const Fmi2String,
) -> Fmi2Status {
    // SAFETY: the caller guarantees n category pointers.
    let categories = unsafe { slice(categories, n) };
    let f = |inst: &mut Instance<M>| -> Outcome {
        let categories = categories.ok_or_else(|| null("categories"))?;
        let mut names = Vec::with_capacity(categories.len());
        for &p in categories {
            if p.is_null() {
                return Err(null("a category"));
            }
            // SAFETY: non-null, and the caller guarantees NUL-terminated strings.
            names.push(unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned());
        }
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        inst.set_debug_logging(on == FMI2_TRUE, &names)
    };
    // SAFETY: see with_instance; c is this library's instance.
    unsafe { with_instance::<M>(c, Call::SetDebugLogging, f) }
}

/// Runs a call without pointer arguments besides the instance.
///
/// # Safety
/// See [`with_instance`].
unsafe fn simple<M: Model>(
    c: Fmi2Component,
    call: Call,
    f: impl FnOnce(&mut Instance<M>) -> Outcome,
) -> Fmi2Status {
    // SAFETY: forwarded contract.
    unsafe { with_instance::<M>(c, call, f) }
}

/// fmi2GetReal / fmi2GetRealOutputDerivatives-style calls: `n` value references in,
/// `n` values out.
///
/// # Safety
/// See [`with_instance`]; `vr` and `values` must hold `n` items.
#[inline(always)]
unsafe fn get_values<M: Model, T>(
    c: Fmi2Component,
    call: Call,
    vr: *const Fmi2ValueReference,
    n: usize,
    values: *mut T,
    f: impl FnOnce(&mut Instance<M>, &[u32], &mut [T]) -> Outcome,
) -> Fmi2Status {
    // SAFETY: the caller guarantees n value references and n writable values.
    let (vrs, values) = unsafe { (slice(vr, n), slice_mut(values, n)) };
    // SAFETY: see with_instance.
    unsafe {
        with_instance::<M>(c, call, |inst| {
            let vrs = vrs.ok_or_else(|| null("vr"))?;
            let values = values.ok_or_else(|| null("value"))?;
            f(inst, vrs, values)
        })
    }
}

/// fmi2SetReal-style calls.
///
/// # Safety
/// See [`with_instance`]; `vr` and `values` must hold `n` items.
#[inline(always)]
unsafe fn set_values<M: Model, T>(
    c: Fmi2Component,
    call: Call,
    vr: *const Fmi2ValueReference,
    n: usize,
    values: *const T,
    f: impl FnOnce(&mut Instance<M>, &[u32], &[T]) -> Outcome,
) -> Fmi2Status {
    // SAFETY: the caller guarantees n value references and n values.
    let (vrs, values) = unsafe { (slice(vr, n), slice(values, n)) };
    // SAFETY: see with_instance.
    unsafe {
        with_instance::<M>(c, call, |inst| {
            let vrs = vrs.ok_or_else(|| null("vr"))?;
            let values = values.ok_or_else(|| null("value"))?;
            f(inst, vrs, values)
        })
    }
}

pub mod fmi3;
pub mod me;
mod state;
mod values;

pub use state::*;
pub use values::*;

#[cfg(test)]
mod tests;
