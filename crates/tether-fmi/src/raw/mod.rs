//! The raw layer: the FMI 2.0 C types and function table, mirrored one-to-one from
//! `fmi2TypesPlatform.h` / `fmi2FunctionTypes.h`, a thin owner of one `fmi2Component`
//! whose methods are named after the C functions, and the single status check every
//! call goes through.
//!
//! This is one of the crate's FFI modules: all `unsafe` calls into the FMU live in
//! `component` (crate-private).

#![allow(non_camel_case_types, non_snake_case, non_upper_case_globals)]

/// A co-simulation function of a function table (FMI 2.0 and 3.0 alike):
/// resolved from `lib` by its name, required when `required` (the FMU
/// declares co-simulation); otherwise a missing one is a function that
/// returns `absent`, never called (co-simulation instances of such an FMU are
/// refused before they are made).
macro_rules! co_simulation_symbol {
    ($lib:ident, $path:ident, $required:ident, $name:ident, ($($arg:ty),*) -> $ret:ty, $absent:expr) => {{
        // SAFETY: the symbol is looked up by its standard name and given the
        // signature the standard's header declares for that name (an FMU that
        // exports another violates the standard, which no importer can
        // detect); the pointer is only used while `lib` stays loaded (the
        // `Library` owning it is held in an `Arc` by every instance).
        let symbol = unsafe { $lib.get::<unsafe extern "C" fn($($arg),*) -> $ret>(stringify!($name)) };
        match symbol {
            Ok(symbol) => *symbol,
            Err(_) if $required => {
                return Err($crate::error::Error::MissingSymbol {
                    library: $path.to_owned(),
                    symbol: stringify!($name),
                })
            }
            Err(_) => {
                unsafe extern "C" fn absent($(_: $arg),*) -> $ret {
                    $absent
                }
                absent
            }
        }
    }};
}

pub mod fmi3;
mod functions;
mod me;

use std::ffi::{c_char, c_int, c_uint, c_void};

pub use functions::Fmi2Functions;
pub(crate) use me::missing as missing_me_symbol;
pub use me::{fmi2EventInfo, Fmi2MeFunctions, Fmi3MeFunctions};

/// `fmi2Component`: the FMU's opaque instance pointer.
pub type fmi2Component = *mut c_void;
/// `fmi2ComponentEnvironment`: the master's opaque pointer handed back in callbacks.
pub type fmi2ComponentEnvironment = *mut c_void;
/// `fmi2FMUstate`: the FMU's opaque state pointer.
pub type fmi2FMUstate = *mut c_void;
/// `fmi2ValueReference`.
pub type fmi2ValueReference = c_uint;
/// `fmi2Real`.
pub type fmi2Real = f64;
/// `fmi2Integer`.
pub type fmi2Integer = c_int;
/// `fmi2Boolean` (`fmi2True` = 1, `fmi2False` = 0).
pub type fmi2Boolean = c_int;
/// `fmi2Char`.
pub type fmi2Char = c_char;
/// `fmi2String`.
pub type fmi2String = *const fmi2Char;
/// `fmi2Byte`.
pub type fmi2Byte = c_char;
/// `fmi2Status` (an `int`-sized C enum; kept as an integer so any value is sound).
pub type fmi2Status = c_int;
/// `fmi2Type`.
pub type fmi2Type = c_int;
/// `fmi2StatusKind`.
pub type fmi2StatusKind = c_int;

/// `fmi2True`.
pub const fmi2True: fmi2Boolean = 1;
/// `fmi2False`.
pub const fmi2False: fmi2Boolean = 0;
/// `fmi2OK`.
pub const fmi2OK: fmi2Status = 0;
/// `fmi2Warning`.
pub const fmi2Warning: fmi2Status = 1;
/// `fmi2Discard`.
pub const fmi2Discard: fmi2Status = 2;
/// `fmi2Error`.
pub const fmi2Error: fmi2Status = 3;
/// `fmi2Fatal`.
pub const fmi2Fatal: fmi2Status = 4;
/// `fmi2Pending`.
pub const fmi2Pending: fmi2Status = 5;
/// `fmi2ModelExchange`.
pub const fmi2ModelExchange: fmi2Type = 0;
/// `fmi2CoSimulation`.
pub const fmi2CoSimulation: fmi2Type = 1;
/// `fmi2DoStepStatus`.
pub const fmi2DoStepStatus: fmi2StatusKind = 0;
/// `fmi2PendingStatus`.
pub const fmi2PendingStatus: fmi2StatusKind = 1;
/// `fmi2LastSuccessfulTime`.
pub const fmi2LastSuccessfulTime: fmi2StatusKind = 2;
/// `fmi2Terminated`.
pub const fmi2Terminated: fmi2StatusKind = 3;

/// `fmi2CallbackLogger` (C-variadic).
pub type fmi2CallbackLogger = Option<
    unsafe extern "C" fn(
        componentEnvironment: fmi2ComponentEnvironment,
        instanceName: fmi2String,
        status: fmi2Status,
        category: fmi2String,
        message: fmi2String,
        ...
    ),
>;
/// `fmi2CallbackAllocateMemory`.
pub type fmi2CallbackAllocateMemory =
    Option<unsafe extern "C" fn(nobj: usize, size: usize) -> *mut c_void>;
/// `fmi2CallbackFreeMemory`.
pub type fmi2CallbackFreeMemory = Option<unsafe extern "C" fn(obj: *mut c_void)>;
/// `fmi2StepFinished`.
pub type fmi2StepFinished = Option<
    unsafe extern "C" fn(componentEnvironment: fmi2ComponentEnvironment, status: fmi2Status),
>;

/// `fmi2CallbackFunctions`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct fmi2CallbackFunctions {
    /// Logger (mandatory).
    pub logger: fmi2CallbackLogger,
    /// `calloc`-like allocator.
    pub allocateMemory: fmi2CallbackAllocateMemory,
    /// `free`-like deallocator.
    pub freeMemory: fmi2CallbackFreeMemory,
    /// Asynchronous step completion (unused: Tether does not run FMUs asynchronously).
    pub stepFinished: fmi2StepFinished,
    /// Handed back as the first argument of `logger` and `stepFinished`.
    pub componentEnvironment: fmi2ComponentEnvironment,
}

/// A returned `fmi2Status`, decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Status {
    /// `fmi2OK`.
    Ok,
    /// `fmi2Warning`.
    Warning,
    /// `fmi2Discard`.
    Discard,
    /// `fmi2Error`.
    Error,
    /// `fmi2Fatal`.
    Fatal,
    /// `fmi2Pending`.
    Pending,
    /// A value outside the enumeration.
    Unknown(i32),
}

impl From<fmi2Status> for Status {
    fn from(code: fmi2Status) -> Self {
        match code {
            fmi2OK => Status::Ok,
            fmi2Warning => Status::Warning,
            fmi2Discard => Status::Discard,
            fmi2Error => Status::Error,
            fmi2Fatal => Status::Fatal,
            fmi2Pending => Status::Pending,
            other => Status::Unknown(other),
        }
    }
}

/// What a status check needs to know about the call it checks.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CallSite<'a> {
    /// The C function name.
    pub function: &'static str,
    /// The instance name.
    pub instance: &'a str,
    /// The instance's communication time.
    pub time: f64,
}

/// The one status check every FMI call goes through: logs the call at trace level,
/// passes OK, logs Warning at warn level and passes it, and turns every other status
/// into the matching typed error.
pub(crate) fn check(site: CallSite<'_>, code: fmi2Status) -> crate::Result<()> {
    // Which standard is asked only of a status other than OK.
    let fmi3 = || site.function.starts_with("fmi3");
    let status = match Status::from(code) {
        // fmi2Pending has no FMI 3.0 counterpart.
        Status::Pending if fmi3() => Status::Unknown(code),
        status => status,
    };
    log::trace!(
        target: "tether_fmi::call",
        "{}({}) at t={} -> {:?}",
        site.function,
        site.instance,
        site.time,
        status
    );
    let function = site.function;
    let time = site.time;
    // The instance name is copied only for an error (OK calls allocate nothing).
    let instance = || site.instance.to_owned();
    match status {
        Status::Ok => Ok(()),
        Status::Warning => {
            let instance = site.instance;
            let api = if fmi3() { "fmi3" } else { "fmi2" };
            log::warn!(
                target: "tether_fmi::call",
                "{function} returned {api}Warning on instance '{instance}' at t={time}"
            );
            Ok(())
        }
        Status::Discard => Err(crate::Error::Discard {
            function,
            instance: instance(),
            time,
            messages: Default::default(),
        }),
        Status::Error => Err(crate::Error::Failed {
            function,
            instance: instance(),
            time,
            messages: Default::default(),
        }),
        Status::Fatal => Err(crate::Error::Fatal {
            function,
            instance: instance(),
            time,
            messages: Default::default(),
        }),
        Status::Pending => Err(crate::Error::Pending {
            function,
            instance: instance(),
            time,
        }),
        Status::Unknown(code) => Err(crate::Error::UnknownStatus {
            function,
            instance: instance(),
            time,
            code,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ok_and_warning_pass_and_the_rest_are_typed_errors() {
        let site = CallSite {
            function: "fmi2DoStep",
            instance: "a",
            time: 0.5,
        };
        assert!(check(site, fmi2OK).is_ok());
        assert!(check(site, fmi2Warning).is_ok());
        assert!(matches!(
            check(site, fmi2Discard),
            Err(crate::Error::Discard { .. })
        ));
        assert!(matches!(
            check(site, fmi2Error),
            Err(crate::Error::Failed { .. })
        ));
        assert!(matches!(
            check(site, fmi2Fatal),
            Err(crate::Error::Fatal { .. })
        ));
        assert!(matches!(
            check(site, fmi2Pending),
            Err(crate::Error::Pending { .. })
        ));
        let e = check(site, 42).unwrap_err();
        assert_eq!(
            e.to_string(),
            "fmi2DoStep returned the unknown status code 42 on instance 'a' at t=0.5"
        );
    }
}
