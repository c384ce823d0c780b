//! The function-pointer table of the FMI 2.0 co-simulation API (common + CS functions;
//! the CS functions optional in the library of an FMU without co-simulation).

use std::ffi::c_char;
use std::path::Path;

use super::*;
use crate::error::{Error, Result};

macro_rules! fmi2_functions {
    (
        $($name:ident: $ty:ty,)*
        ; co_simulation {
            $($cs:ident: ($($arg:ty),*) -> $ret:ty = $absent:expr,)*
        }
    ) => {
        /// Every function of the FMI 2.0 co-simulation API, resolved from the FMU's
        /// shared library. Field names are the C symbol names.
        #[derive(Clone, Copy)]
        pub struct Fmi2Functions {
            $(
                #[doc = concat!("`", stringify!($name), "`.")]
                pub $name: $ty,
            )*
            $(
                #[doc = concat!("`", stringify!($cs), "` (co-simulation only).")]
                pub $cs: unsafe extern "C" fn($($arg),*) -> $ret,
            )*
        }

        impl Fmi2Functions {
            /// The C symbol names, in table order.
            pub const SYMBOLS: &'static [&'static str] =
                &[$(stringify!($name),)* $(stringify!($cs)),*];

            /// Resolves every function, naming the first one that is missing. The
            /// co-simulation functions are required when `co_simulation` (the FMU
            /// declares co-simulation); otherwise a missing one is replaced by a
            /// function returning fmi2Error, which is never called (co-simulation
            /// instances of such an FMU are refused before they are made).
            pub(crate) fn resolve(
                lib: &libloading::Library,
                path: &Path,
                co_simulation: bool,
            ) -> Result<Self> {
                Ok(Fmi2Functions {
                    $(
                        $name: {
                            // SAFETY: the symbol is looked up by its FMI 2.0 name and given
                            // the signature fmi2FunctionTypes.h declares for that name; an FMU
                            // exporting a different signature under a standard name violates
                            // the standard, which no importer can detect. The pointer is only
                            // used while `lib` stays loaded (the `Library` owning it is held
                            // in an `Arc` by every instance).
                            let symbol = unsafe { lib.get::<$ty>(stringify!($name)) };
                            *symbol.map_err(|_| Error::MissingSymbol {
                                library: path.to_owned(),
                                symbol: stringify!($name),
                            })?
                        },
                    )*
                    $(
                        $cs: co_simulation_symbol!(
                            lib, path, co_simulation, $cs, ($($arg),*) -> $ret, $absent
                        ),
                    )*
                })
            }
        }
    };
}

type C = fmi2Component;
type Vr = *const fmi2ValueReference;

fmi2_functions! {
    fmi2GetTypesPlatform: unsafe extern "C" fn() -> *const c_char,
    fmi2GetVersion: unsafe extern "C" fn() -> *const c_char,
    fmi2SetDebugLogging: unsafe extern "C" fn(C, fmi2Boolean, usize, *const fmi2String) -> fmi2Status,
    fmi2Instantiate: unsafe extern "C" fn(
        fmi2String,
        fmi2Type,
        fmi2String,
        fmi2String,
        *const fmi2CallbackFunctions,
        fmi2Boolean,
        fmi2Boolean,
    ) -> fmi2Component,
    fmi2FreeInstance: unsafe extern "C" fn(C),
    fmi2SetupExperiment: unsafe extern "C" fn(C, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real) -> fmi2Status,
    fmi2EnterInitializationMode: unsafe extern "C" fn(C) -> fmi2Status,
    fmi2ExitInitializationMode: unsafe extern "C" fn(C) -> fmi2Status,
    fmi2Terminate: unsafe extern "C" fn(C) -> fmi2Status,
    fmi2Reset: unsafe extern "C" fn(C) -> fmi2Status,
    fmi2GetReal: unsafe extern "C" fn(C, Vr, usize, *mut fmi2Real) -> fmi2Status,
    fmi2GetInteger: unsafe extern "C" fn(C, Vr, usize, *mut fmi2Integer) -> fmi2Status,
    fmi2GetBoolean: unsafe extern "C" fn(C, Vr, usize, *mut fmi2Boolean) -> fmi2Status,
    fmi2GetString: unsafe extern "C" fn(C, Vr, usize, *mut fmi2String) -> fmi2Status,
    fmi2SetReal: unsafe extern "C" fn(C, Vr, usize, *const fmi2Real) -> fmi2Status,
    fmi2SetInteger: unsafe extern "C" fn(C, Vr, usize, *const fmi2Integer) -> fmi2Status,
    fmi2SetBoolean: unsafe extern "C" fn(C, Vr, usize, *const fmi2Boolean) -> fmi2Status,
    fmi2SetString: unsafe extern "C" fn(C, Vr, usize, *const fmi2String) -> fmi2Status,
    fmi2GetFMUstate: unsafe extern "C" fn(C, *mut fmi2FMUstate) -> fmi2Status,
    fmi2SetFMUstate: unsafe extern "C" fn(C, fmi2FMUstate) -> fmi2Status,
    fmi2FreeFMUstate: unsafe extern "C" fn(C, *mut fmi2FMUstate) -> fmi2Status,
    fmi2SerializedFMUstateSize: unsafe extern "C" fn(C, fmi2FMUstate, *mut usize) -> fmi2Status,
    fmi2SerializeFMUstate: unsafe extern "C" fn(C, fmi2FMUstate, *mut fmi2Byte, usize) -> fmi2Status,
    fmi2DeSerializeFMUstate: unsafe extern "C" fn(C, *const fmi2Byte, usize, *mut fmi2FMUstate) -> fmi2Status,
    fmi2GetDirectionalDerivative: unsafe extern "C" fn(C, Vr, usize, Vr, usize, *const fmi2Real, *mut fmi2Real) -> fmi2Status,
    ; co_simulation {
        fmi2SetRealInputDerivatives: (C, Vr, usize, *const fmi2Integer, *const fmi2Real) -> fmi2Status = fmi2Error,
        fmi2GetRealOutputDerivatives: (C, Vr, usize, *const fmi2Integer, *mut fmi2Real) -> fmi2Status = fmi2Error,
        fmi2DoStep: (C, fmi2Real, fmi2Real, fmi2Boolean) -> fmi2Status = fmi2Error,
        fmi2CancelStep: (C) -> fmi2Status = fmi2Error,
        fmi2GetStatus: (C, fmi2StatusKind, *mut fmi2Status) -> fmi2Status = fmi2Error,
        fmi2GetRealStatus: (C, fmi2StatusKind, *mut fmi2Real) -> fmi2Status = fmi2Error,
        fmi2GetIntegerStatus: (C, fmi2StatusKind, *mut fmi2Integer) -> fmi2Status = fmi2Error,
        fmi2GetBooleanStatus: (C, fmi2StatusKind, *mut fmi2Boolean) -> fmi2Status = fmi2Error,
        fmi2GetStringStatus: (C, fmi2StatusKind, *mut fmi2String) -> fmi2Status = fmi2Error,
    }
}

impl std::fmt::Debug for Fmi2Functions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fmi2Functions")
            .field("symbols", &Self::SYMBOLS.len())
            .finish_non_exhaustive()
    }
}
