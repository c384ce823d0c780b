//! The C side: every `fmi2*` function of the co-simulation interface, on the
//! FMI types, the state table and the logger of the FMU kit
//! (`tether_fmu_kit::ffi`, `machine`). Each function checks its pointers,
//! runs the call inside `catch_unwind` (a panic becomes fmi2Fatal, logged)
//! and logs a failure through the importer's logger of that instance. An
//! instance owns all its data: instances share nothing. The FMI 3.0 layer
//! ([`crate::ffi3`]) runs its calls through the same [`with`] on the same
//! [`Component`], with its own [`Logger`].

#![allow(non_snake_case, clippy::missing_safety_doc)]

use std::cell::Cell;
use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::ptr;

use tether_fmu_kit::ffi::fmi3::{Fmi3Status, IntermediateUpdate};
use tether_fmu_kit::ffi::{
    null, slice, slice_mut, EnvironmentLogger, Fmi2Boolean as B, Fmi2CallbackFunctions,
    Fmi2Component as C, Fmi2FmuState as S, Fmi2Status as St, Fmi2String as Str,
    Fmi2ValueReference as Vr,
};
use tether_fmu_kit::instance::{Failure, Outcome, Status};
use tether_fmu_kit::machine::{Call, MachineState};

use crate::runtime::{uri_path, Exported, Saved};

pub(crate) const OK: St = Status::Ok as St;
pub(crate) const ERROR: St = Status::Error as St;

/// The importer's logger of one instance: FMI 2.0's `fmi2CallbackLogger`
/// (with the instance name) or FMI 3.0's `fmi3LogMessageCallback`.
#[derive(Clone, Copy)]
pub(crate) enum Logger {
    Fmi2(EnvironmentLogger),
    Fmi3 {
        callback: unsafe extern "C" fn(*mut c_void, Fmi3Status, *const c_char, *const c_char),
        environment: *mut c_void,
    },
}

impl Logger {
    fn log(&self, status: Status, category: &str, message: &str) {
        match *self {
            Logger::Fmi2(logger) => logger.log(status, category, message),
            Logger::Fmi3 {
                callback,
                environment,
            } => {
                let category = c_string(category);
                let message = c_string(message);
                // SAFETY: the callback and environment fmi3InstantiateCoSimulation
                // received, valid until fmi3FreeInstance (the FMI contract); both
                // strings are NUL-terminated and live across the call.
                unsafe {
                    callback(
                        environment,
                        status as Fmi3Status,
                        category.as_ptr(),
                        message.as_ptr(),
                    )
                }
            }
        }
    }
}

/// What a component pointer points at.
pub(crate) struct Component {
    exported: Exported,
    logger: Option<Logger>,
    logging_on: bool,
    /// Made by fmi3InstantiateCoSimulation: messages name the fmi3 functions.
    fmi3: bool,
    /// FMI 3.0: the importer's intermediate update callback and its
    /// instance environment, if it gave one ([`crate::ffi3::fmi3DoStep`]).
    pub(crate) intermediate_update: Option<(IntermediateUpdate, *mut c_void)>,
    /// In intermediate update mode (the importer's callback runs): only
    /// inputs may be set.
    pub(crate) intermediate: bool,
    /// The instance name `logger.instance_name` points into.
    _name: CString,
}

impl Component {
    /// Errors are always logged, the rest with debug logging on.
    fn log(&self, status: Status, message: &str) {
        let category = match status {
            Status::Ok => "logEvents",
            Status::Warning => "logStatusWarning",
            Status::Discard => "logStatusDiscard",
            Status::Error => "logStatusError",
            Status::Fatal => "logStatusFatal",
        };
        if let Some(logger) = &self.logger {
            if self.logging_on || status as i32 >= Status::Error as i32 {
                logger.log(status, category, message);
            }
        }
    }

    fn fail(&mut self, call: Call, failure: Failure) -> St {
        if failure.status == Status::Fatal {
            self.exported.machine = MachineState::Fatal;
        } else if failure.enters_error_state {
            self.exported.machine = MachineState::Error;
        }
        let function = if self.fmi3 {
            call.fmi3_name()
        } else {
            call.name()
        };
        self.log(failure.status, &format!("{function}: {}", failure.message));
        failure.status as St
    }
}

thread_local! {
    /// The logger of the instance whose call runs on this thread, and
    /// whether its debug logging is on: where the members' messages and the
    /// master's warnings (the `log` facade) go.
    static IN_CALL: Cell<Option<(Logger, bool)>> = const { Cell::new(None) };
}

/// Puts an instance's logger in scope for one call; the previous one comes
/// back on drop (also after a panic).
struct Scope(Option<(Logger, bool)>);

impl Scope {
    fn enter(logger: Option<Logger>, logging_on: bool) -> Scope {
        Scope(IN_CALL.replace(logger.map(|l| (l, logging_on))))
    }
}

impl Drop for Scope {
    fn drop(&mut self) {
        IN_CALL.set(self.0);
    }
}

/// Forwards `log` records (the member FMUs' messages, as tether-fmi
/// reports them, and the master's) to the importer's logger of the instance
/// in the call: warnings and errors always, the rest with debug logging on.
struct Forward;

impl log::Log for Forward {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        IN_CALL
            .get()
            .is_some_and(|(_, on)| on || metadata.level() <= log::Level::Warn)
    }

    fn log(&self, record: &log::Record) {
        let Some((logger, on)) = IN_CALL.get() else {
            return;
        };
        let (status, category) = match record.level() {
            log::Level::Error => (Status::Error, "logStatusError"),
            log::Level::Warn => (Status::Warning, "logStatusWarning"),
            _ if on => (Status::Ok, "logEvents"),
            _ => return,
        };
        // A member FMU's message names the member (`fmu::<instance>`); the
        // system's own say what they say, without a Rust module path.
        let message = if record.target().starts_with("fmu::") {
            format!("{}: {}", record.target(), record.args())
        } else {
            record.args().to_string()
        };
        logger.log(status, category, &message);
    }

    fn flush(&self) {}
}

/// Installs [`Forward`] once per process (this library's own `log` facade).
fn forward_log() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if log::set_logger(&Forward).is_ok() {
            log::set_max_level(log::LevelFilter::Info);
        }
    });
}

pub(crate) fn c_string(text: &str) -> CString {
    CString::new(text.replace('\0', " ")).unwrap_or_default()
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    let text = payload.downcast_ref::<&str>().map(|s| s.to_string());
    text.or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

/// Runs `f` on the instance behind `c` after the state-table check; a
/// failure is logged and applied, a panic becomes fmi2Fatal.
///
/// # Safety
/// `c` must be null or a live pointer from [`fmi2Instantiate`] or
/// `fmi3InstantiateCoSimulation`.
pub(crate) unsafe fn with(c: C, call: Call, f: impl FnOnce(&mut Exported) -> Outcome) -> St {
    if c.is_null() {
        return ERROR;
    }
    // SAFETY: per the contract, c is a live Box<Component> from fmi2Instantiate.
    let component = unsafe { &mut *c.cast::<Component>() };
    let _scope = Scope::enter(component.logger, component.logging_on);
    let exported = &mut component.exported;
    let intermediate = component.intermediate;
    let result = catch_unwind(AssertUnwindSafe(|| {
        let state = exported.machine;
        if intermediate && !matches!(call, Call::SetReal) {
            Err(Failure::usage(
                "not allowed in intermediate update mode (only fmi3SetFloat64 of inputs)",
            ))
        } else if call.allowed_in(state) {
            f(exported)
        } else {
            Err(Failure::usage(format!("not allowed in state {state:?}")))
        }
    }));
    let failure = match result {
        Ok(Ok(())) => return OK,
        Ok(Err(failure)) => failure,
        Err(payload) => Failure {
            status: Status::Fatal,
            message: format!("panic: {}", panic_message(payload.as_ref())),
            enters_error_state: true,
        },
    };
    let status = catch_unwind(AssertUnwindSafe(|| component.fail(call, failure)));
    status.unwrap_or(Status::Fatal as St)
}

/// FMI 3.0: the importer's intermediate update callback and environment of
/// the instance behind `c` (`None` for null or without one).
///
/// # Safety
/// As [`with`].
pub(crate) unsafe fn intermediate_update(c: C) -> Option<(IntermediateUpdate, *mut c_void)> {
    // SAFETY: c is null or a live Box<Component> (the caller's contract); the
    // borrow ends with this statement.
    (!c.is_null())
        .then(|| unsafe { (*c.cast::<Component>()).intermediate_update })
        .flatten()
}

/// Enters (`true`) or leaves intermediate update mode: while the importer's
/// callback runs, [`with`] refuses every call but setting inputs.
///
/// # Safety
/// As [`with`]; no reference to the instance is live.
pub(crate) unsafe fn set_intermediate(c: C, on: bool) {
    if !c.is_null() {
        // SAFETY: c is a live Box<Component> (the caller's contract); the
        // borrow ends with this statement.
        unsafe { (*c.cast::<Component>()).intermediate = on };
    }
}

/// # Safety
/// `p` null or NUL-terminated.
pub(crate) unsafe fn text(p: Str) -> Option<String> {
    // SAFETY: non-null, and the caller guarantees a NUL-terminated string.
    (!p.is_null()).then(|| unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned())
}

#[unsafe(no_mangle)]
pub extern "C" fn fmi2GetTypesPlatform() -> *const c_char {
    tether_fmu_kit::ffi::get_types_platform()
}

#[unsafe(no_mangle)]
pub extern "C" fn fmi2GetVersion() -> *const c_char {
    tether_fmu_kit::ffi::get_version()
}

/// A new instance of the system in `resources` (checked against `guid`),
/// boxed as a component pointer; null with the reason logged (as a message
/// of the instantiate function of the FMI version) otherwise. `fmi3`: made
/// by fmi3InstantiateCoSimulation, with the importer's intermediate update
/// callback if it gave one.
pub(crate) fn instantiate(
    name: CString,
    logger: Option<Logger>,
    logging_on: bool,
    fmi3: Option<Option<(IntermediateUpdate, *mut c_void)>>,
    resources: Result<std::path::PathBuf, String>,
    guid: Option<String>,
) -> C {
    forward_log();
    let _scope = Scope::enter(logger, logging_on);
    let exported = resources.and_then(|r| Exported::new(&r, guid.as_deref().unwrap_or("")));
    match exported {
        Ok(exported) => {
            let component = Component {
                exported,
                logger,
                logging_on,
                fmi3: fmi3.is_some(),
                intermediate_update: fmi3.flatten(),
                intermediate: false,
                _name: name,
            };
            Box::into_raw(Box::new(component)).cast::<c_void>()
        }
        Err(reason) => {
            if let Some(logger) = logger {
                let function = if fmi3.is_some() {
                    "fmi3InstantiateCoSimulation"
                } else {
                    "fmi2Instantiate"
                };
                let message = format!("{function}: {reason}");
                logger.log(Status::Error, "logStatusError", &message);
            }
            ptr::null_mut()
        }
    }
}

/// Null with a logged reason when the resources are missing or broken.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2Instantiate(
    name: Str,
    fmu_type: c_int,
    guid: Str,
    resources: Str,
    functions: *const Fmi2CallbackFunctions,
    _visible: B,
    logging_on: B,
) -> C {
    let made = catch_unwind(AssertUnwindSafe(|| {
        if functions.is_null() {
            return ptr::null_mut();
        }
        // SAFETY: the FMI contract: a NUL-terminated name or null.
        let Some(name) = (unsafe { text(name) }) else {
            return ptr::null_mut();
        };
        // SAFETY: non-null, and the FMI contract gives a valid callback struct.
        let callbacks = unsafe { &*functions };
        let name = c_string(&name);
        let logger = callbacks.logger.map(|logger| {
            Logger::Fmi2(EnvironmentLogger {
                logger,
                component_environment: callbacks.component_environment,
                instance_name: name.as_ptr(),
            })
        });
        // SAFETY: the FMI contract: NUL-terminated strings or null.
        let (guid, resources) = unsafe { (text(guid), text(resources)) };
        let resources = if fmu_type != 1 {
            Err("this FMU supports co-simulation only (fmuType must be fmi2CoSimulation)".into())
        } else {
            resources
                .ok_or_else(|| "no fmuResourceLocation given".to_string())
                .and_then(|r| uri_path(&r))
        };
        instantiate(name, logger, logging_on != 0, None, resources, guid)
    }));
    made.unwrap_or(ptr::null_mut())
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2FreeInstance(c: C) {
    if !c.is_null() {
        // SAFETY: c came from Box::into_raw in fmi2Instantiate and is freed only here.
        let component = unsafe { Box::from_raw(c.cast::<Component>()) };
        let _ = catch_unwind(AssertUnwindSafe(|| drop(component)));
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2SetDebugLogging(
    c: C,
    on: B,
    _n: usize,
    _categories: *const Str,
) -> St {
    if c.is_null() {
        return ERROR;
    }
    // SAFETY: a live Box<Component> from fmi2Instantiate (the FMI contract).
    unsafe { &mut *c.cast::<Component>() }.logging_on = on != 0;
    OK
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2SetupExperiment(
    c: C,
    _tol_defined: B,
    _tol: f64,
    start: f64,
    stop_defined: B,
    stop: f64,
) -> St {
    let stop = (stop_defined != 0).then_some(stop);
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::SetupExperiment, |e| {
            e.setup_experiment(start, stop)
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2EnterInitializationMode(c: C) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::EnterInitializationMode, |e| {
            e.machine = MachineState::InitializationMode;
            Ok(())
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2ExitInitializationMode(c: C) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::ExitInitializationMode, |e| {
            e.exit_initialization_mode()?;
            e.machine = MachineState::StepComplete;
            Ok(())
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2Terminate(c: C) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::Terminate, |e| {
            e.machine = MachineState::Terminated;
            Ok(())
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2Reset(c: C) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::Reset, |e| {
            e.reset();
            e.machine = MachineState::Instantiated;
            Ok(())
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2GetReal(c: C, vr: *const Vr, n: usize, v: *mut f64) -> St {
    // SAFETY: the FMI contract: n value references and n writable values.
    let (vr, v) = unsafe { (slice(vr, n), slice_mut(v, n)) };
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::GetReal, |e| {
            e.get_real(
                vr.ok_or_else(|| null("vr"))?,
                v.ok_or_else(|| null("value"))?,
            )
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2SetReal(c: C, vr: *const Vr, n: usize, v: *const f64) -> St {
    // SAFETY: the FMI contract: n value references and n values.
    let (vr, v) = unsafe { (slice(vr, n), slice(v, n)) };
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::SetReal, |e| {
            e.set_real(
                vr.ok_or_else(|| null("vr"))?,
                v.ok_or_else(|| null("value"))?,
            )
        })
    }
}

/// The exported FMU has Real variables only: any Integer, Boolean or String
/// value reference is refused.
///
/// # Safety
/// See `with`.
unsafe fn no_such(c: C, call: Call, n: usize, kind: &str) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, call, |_| match n {
            0 => Ok(()),
            _ => Err(Failure::usage(format!("the FMU has no {kind} variables"))),
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2GetInteger(c: C, _vr: *const Vr, n: usize, _v: *mut c_int) -> St {
    // SAFETY: see no_such.
    unsafe { no_such(c, Call::GetInteger, n, "Integer") }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2GetBoolean(c: C, _vr: *const Vr, n: usize, _v: *mut B) -> St {
    // SAFETY: see no_such.
    unsafe { no_such(c, Call::GetBoolean, n, "Boolean") }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2GetString(c: C, _vr: *const Vr, n: usize, _v: *mut Str) -> St {
    // SAFETY: see no_such.
    unsafe { no_such(c, Call::GetString, n, "String") }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2SetInteger(c: C, _vr: *const Vr, n: usize, _v: *const c_int) -> St {
    // SAFETY: see no_such.
    unsafe { no_such(c, Call::SetInteger, n, "Integer") }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2SetBoolean(c: C, _vr: *const Vr, n: usize, _v: *const B) -> St {
    // SAFETY: see no_such.
    unsafe { no_such(c, Call::SetBoolean, n, "Boolean") }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2SetString(c: C, _vr: *const Vr, n: usize, _v: *const Str) -> St {
    // SAFETY: see no_such.
    unsafe { no_such(c, Call::SetString, n, "String") }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2DoStep(c: C, t: f64, h: f64, _no_prior: B) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe { with(c, Call::DoStep, |e| e.do_step(t, h)) }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2GetFMUstate(c: C, s: *mut S) -> St {
    // SAFETY: the FMI contract (see `with`); s is checked for null.
    unsafe {
        with(c, Call::GetFMUstate, |e| {
            if s.is_null() {
                return Err(null("FMUstate"));
            }
            let saved = e.get_state()?;
            // SAFETY (of the enclosing block): s is non-null and writable
            // (FMI contract); a non-null *s is a state of this FMU from
            // fmi2GetFMUstate, reused here.
            if (*s).is_null() {
                *s = Box::into_raw(Box::new(saved)).cast::<c_void>();
            } else {
                *(*s).cast::<Saved>() = saved;
            }
            Ok(())
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2SetFMUstate(c: C, s: S) -> St {
    // SAFETY: the FMI contract (see `with`); s is checked for null.
    unsafe {
        with(c, Call::SetFMUstate, |e| {
            if s.is_null() {
                return Err(null("FMUstate"));
            }
            // SAFETY: a non-null state from this FMU's fmi2GetFMUstate.
            e.set_state(&*s.cast::<Saved>())
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2FreeFMUstate(c: C, s: *mut S) -> St {
    // SAFETY: the FMI contract (see `with`); s and *s are checked for null.
    unsafe {
        with(c, Call::FreeFMUstate, |_| {
            if !s.is_null() && !(*s).is_null() {
                // SAFETY: *s came from Box::into_raw in fmi2GetFMUstate.
                drop(Box::from_raw((*s).cast::<Saved>()));
                *s = ptr::null_mut();
            }
            Ok(())
        })
    }
}

/// The state functions the FMU declares it lacks, and the other optional
/// ones: fmi2Error with the reason.
///
/// # Safety
/// See `with`.
unsafe fn unsupported(c: C, call: Call, reason: &str) -> St {
    // SAFETY: the FMI contract (see `with`).
    unsafe { with(c, call, |_| Err(Failure::usage(reason.to_string()))) }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2SerializedFMUstateSize(c: C, s: S, size: *mut usize) -> St {
    // SAFETY: the FMI contract (see `with`); s and size are checked for null.
    unsafe {
        with(c, Call::SerializedFMUstateSize, |e| {
            if s.is_null() || size.is_null() {
                return Err(null(if s.is_null() { "FMUstate" } else { "size" }));
            }
            // SAFETY (of the enclosing block): s is a state of this FMU's
            // fmi2GetFMUstate or fmi2DeSerializeFMUstate, size is writable.
            *size = e.serialize(&mut *s.cast::<Saved>())?.len();
            Ok(())
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2SerializeFMUstate(c: C, s: S, b: *mut c_char, n: usize) -> St {
    // SAFETY: the FMI contract: n writable bytes at b (checked for null).
    let buffer = unsafe { slice_mut(b.cast::<u8>(), n) };
    // SAFETY: the FMI contract (see `with`); s is checked for null.
    unsafe {
        with(c, Call::SerializeFMUstate, |e| {
            if s.is_null() {
                return Err(null("FMUstate"));
            }
            let buffer = buffer.ok_or_else(|| null("serializedState"))?;
            // SAFETY (of the enclosing block): a state of this FMU.
            let bytes = e.serialize(&mut *s.cast::<Saved>())?;
            if buffer.len() < bytes.len() {
                return Err(Failure::usage(format!(
                    "a buffer of {} bytes for a state of {} (fmi2SerializedFMUstateSize)",
                    buffer.len(),
                    bytes.len()
                )));
            }
            buffer[..bytes.len()].copy_from_slice(bytes);
            Ok(())
        })
    }
}

#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2DeSerializeFMUstate(
    c: C,
    b: *const c_char,
    n: usize,
    s: *mut S,
) -> St {
    // SAFETY: the FMI contract: n readable bytes at b (checked for null).
    let bytes = unsafe { slice(b.cast::<u8>(), n) };
    // SAFETY: the FMI contract (see `with`); s is checked for null.
    unsafe {
        with(c, Call::DeSerializeFMUstate, |e| {
            if s.is_null() {
                return Err(null("FMUstate"));
            }
            let saved = e.deserialize(bytes.ok_or_else(|| null("serializedState"))?)?;
            // SAFETY (of the enclosing block): s is writable; a non-null *s is
            // a state of this FMU, reused here.
            if (*s).is_null() {
                *s = Box::into_raw(Box::new(saved)).cast::<c_void>();
            } else {
                *(*s).cast::<Saved>() = saved;
            }
            Ok(())
        })
    }
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
    // SAFETY: see unsupported.
    unsafe {
        unsupported(
            c,
            Call::GetDirectionalDerivative,
            "providesDirectionalDerivative is false",
        )
    }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2SetRealInputDerivatives(
    c: C,
    vr: *const Vr,
    n: usize,
    order: *const c_int,
    v: *const f64,
) -> St {
    // SAFETY: the FMI contract: n value references, orders and values.
    let (vr, order, v) = unsafe { (slice(vr, n), slice(order, n), slice(v, n)) };
    // SAFETY: the FMI contract (see `with`).
    unsafe {
        with(c, Call::SetRealInputDerivatives, |e| {
            e.set_input_derivatives(
                vr.ok_or_else(|| null("vr"))?,
                order.ok_or_else(|| null("order"))?,
                v.ok_or_else(|| null("value"))?,
            )
        })
    }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2GetRealOutputDerivatives(
    c: C,
    _vr: *const Vr,
    _n: usize,
    _order: *const c_int,
    _v: *mut f64,
) -> St {
    // SAFETY: see unsupported.
    unsafe {
        unsupported(
            c,
            Call::GetRealOutputDerivatives,
            "maxOutputDerivativeOrder is 0",
        )
    }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2CancelStep(c: C) -> St {
    // SAFETY: see unsupported.
    unsafe {
        unsupported(
            c,
            Call::CancelStep,
            "fmi2DoStep never runs asynchronously: there is nothing to cancel",
        )
    }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2GetStatus(c: C, _kind: c_int, _v: *mut c_int) -> St {
    // SAFETY: see unsupported.
    unsafe { unsupported(c, Call::GetStatus, "no asynchronous step: no status") }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2GetRealStatus(c: C, kind: c_int, v: *mut f64) -> St {
    // SAFETY: the FMI contract (see `with`); v is checked for null.
    unsafe {
        with(c, Call::GetRealStatus, |e| {
            // fmi2LastSuccessfulTime = 2.
            match (kind, e.time()) {
                (2, Some(t)) if !v.is_null() => {
                    // SAFETY: non-null and writable (FMI contract).
                    *v = t;
                    Ok(())
                }
                _ => Err(Failure::usage(format!("no Real status of kind {kind}"))),
            }
        })
    }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2GetIntegerStatus(c: C, _kind: c_int, _v: *mut c_int) -> St {
    // SAFETY: see unsupported.
    unsafe { unsupported(c, Call::GetIntegerStatus, "no Integer status") }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2GetBooleanStatus(c: C, kind: c_int, v: *mut B) -> St {
    // SAFETY: the FMI contract (see `with`); v is checked for null.
    unsafe {
        with(c, Call::GetBooleanStatus, |_| {
            // fmi2Terminated = 3: the system never asks to end early here.
            match kind {
                3 if !v.is_null() => {
                    // SAFETY: non-null and writable (FMI contract).
                    *v = 0;
                    Ok(())
                }
                _ => Err(Failure::usage(format!("no Boolean status of kind {kind}"))),
            }
        })
    }
}
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fmi2GetStringStatus(c: C, _kind: c_int, _v: *mut Str) -> St {
    // SAFETY: see unsupported.
    unsafe { unsupported(c, Call::GetStringStatus, "no String status") }
}
