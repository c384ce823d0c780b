//! The function-pointer table of the FMI 3.0 co-simulation API (the common functions,
//! the getters and setters of every type, FMU states, output derivatives and
//! `fmi3DoStep`).

use std::ffi::c_char;
use std::path::Path;

use super::*;
use crate::error::{Error, Result};

macro_rules! fmi3_functions {
    (
        $($name:ident: $ty:ty,)*
        ; co_simulation {
            $($cs:ident: ($($arg:ty),*) -> $ret:ty = $absent:expr,)*
        }
    ) => {
        /// The FMI 3.0 functions Tether calls, resolved from the FMU's shared library.
        /// Field names are the C symbol names.
        #[derive(Clone, Copy)]
        pub struct Fmi3Functions {
            $(
                #[doc = concat!("`", stringify!($name), "`.")]
                pub $name: $ty,
            )*
            $(
                #[doc = concat!("`", stringify!($cs), "` (co-simulation only).")]
                pub $cs: unsafe extern "C" fn($($arg),*) -> $ret,
            )*
        }

        impl Fmi3Functions {
            /// The C symbol names, in table order.
            pub const SYMBOLS: &'static [&'static str] =
                &[$(stringify!($name),)* $(stringify!($cs)),*];

            /// Resolves every function, naming the first one that is missing. The
            /// co-simulation functions are required when `co_simulation` (the FMU
            /// declares co-simulation); otherwise a missing one is replaced by a
            /// function returning an error (or NULL), which is never called
            /// (co-simulation instances of such an FMU are refused before they are
            /// made).
            pub(crate) fn resolve(
                lib: &libloading::Library,
                path: &Path,
                co_simulation: bool,
            ) -> Result<Self> {
                Ok(Fmi3Functions {
                    $(
                        $name: {
                            // SAFETY: the symbol is looked up by its FMI 3.0 name and given
                            // the signature fmi3FunctionTypes.h declares for that name; an FMU
                            // exporting another signature under a standard name violates the
                            // standard, which no importer can detect. The pointer is only used
                            // while `lib` stays loaded (the `Library` owning it is held in an
                            // `Arc` by every instance).
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

type I = fmi3Instance;
type Vr = *const fmi3ValueReference;
type B = fmi3Boolean;
type S = fmi3Status;

fmi3_functions! {
    fmi3GetVersion: unsafe extern "C" fn() -> *const c_char,
    fmi3SetDebugLogging: unsafe extern "C" fn(I, B, usize, *const fmi3String) -> S,
    fmi3FreeInstance: unsafe extern "C" fn(I),
    fmi3EnterInitializationMode: unsafe extern "C" fn(I, B, f64, f64, B, f64) -> S,
    fmi3ExitInitializationMode: unsafe extern "C" fn(I) -> S,
    fmi3EnterConfigurationMode: unsafe extern "C" fn(I) -> S,
    fmi3ExitConfigurationMode: unsafe extern "C" fn(I) -> S,
    fmi3Terminate: unsafe extern "C" fn(I) -> S,
    fmi3Reset: unsafe extern "C" fn(I) -> S,
    fmi3GetFloat32: unsafe extern "C" fn(I, Vr, usize, *mut f32, usize) -> S,
    fmi3GetFloat64: unsafe extern "C" fn(I, Vr, usize, *mut f64, usize) -> S,
    fmi3GetInt8: unsafe extern "C" fn(I, Vr, usize, *mut i8, usize) -> S,
    fmi3GetUInt8: unsafe extern "C" fn(I, Vr, usize, *mut u8, usize) -> S,
    fmi3GetInt16: unsafe extern "C" fn(I, Vr, usize, *mut i16, usize) -> S,
    fmi3GetUInt16: unsafe extern "C" fn(I, Vr, usize, *mut u16, usize) -> S,
    fmi3GetInt32: unsafe extern "C" fn(I, Vr, usize, *mut i32, usize) -> S,
    fmi3GetUInt32: unsafe extern "C" fn(I, Vr, usize, *mut u32, usize) -> S,
    fmi3GetInt64: unsafe extern "C" fn(I, Vr, usize, *mut i64, usize) -> S,
    fmi3GetUInt64: unsafe extern "C" fn(I, Vr, usize, *mut u64, usize) -> S,
    fmi3GetBoolean: unsafe extern "C" fn(I, Vr, usize, *mut B, usize) -> S,
    fmi3GetString: unsafe extern "C" fn(I, Vr, usize, *mut fmi3String, usize) -> S,
    fmi3GetBinary: unsafe extern "C" fn(I, Vr, usize, *mut usize, *mut fmi3Binary, usize) -> S,
    fmi3SetFloat32: unsafe extern "C" fn(I, Vr, usize, *const f32, usize) -> S,
    fmi3SetFloat64: unsafe extern "C" fn(I, Vr, usize, *const f64, usize) -> S,
    fmi3SetInt8: unsafe extern "C" fn(I, Vr, usize, *const i8, usize) -> S,
    fmi3SetUInt8: unsafe extern "C" fn(I, Vr, usize, *const u8, usize) -> S,
    fmi3SetInt16: unsafe extern "C" fn(I, Vr, usize, *const i16, usize) -> S,
    fmi3SetUInt16: unsafe extern "C" fn(I, Vr, usize, *const u16, usize) -> S,
    fmi3SetInt32: unsafe extern "C" fn(I, Vr, usize, *const i32, usize) -> S,
    fmi3SetUInt32: unsafe extern "C" fn(I, Vr, usize, *const u32, usize) -> S,
    fmi3SetInt64: unsafe extern "C" fn(I, Vr, usize, *const i64, usize) -> S,
    fmi3SetUInt64: unsafe extern "C" fn(I, Vr, usize, *const u64, usize) -> S,
    fmi3SetBoolean: unsafe extern "C" fn(I, Vr, usize, *const B, usize) -> S,
    fmi3SetString: unsafe extern "C" fn(I, Vr, usize, *const fmi3String, usize) -> S,
    fmi3SetBinary: unsafe extern "C" fn(I, Vr, usize, *const usize, *const fmi3Binary, usize) -> S,
    fmi3GetFMUState: unsafe extern "C" fn(I, *mut fmi3FMUState) -> S,
    fmi3SetFMUState: unsafe extern "C" fn(I, fmi3FMUState) -> S,
    fmi3FreeFMUState: unsafe extern "C" fn(I, *mut fmi3FMUState) -> S,
    fmi3SerializedFMUStateSize: unsafe extern "C" fn(I, fmi3FMUState, *mut usize) -> S,
    fmi3SerializeFMUState: unsafe extern "C" fn(I, fmi3FMUState, *mut fmi3Byte, usize) -> S,
    fmi3DeserializeFMUState: unsafe extern "C" fn(I, *const fmi3Byte, usize, *mut fmi3FMUState) -> S,
    ; co_simulation {
        fmi3InstantiateCoSimulation: (
            fmi3String,
            fmi3String,
            fmi3String,
            B,
            B,
            B,
            B,
            Vr,
            usize,
            fmi3InstanceEnvironment,
            fmi3LogMessageCallback,
            fmi3IntermediateUpdateCallback
        ) -> fmi3Instance = std::ptr::null_mut(),
        fmi3GetOutputDerivatives: (I, Vr, usize, *const i32, *mut f64, usize) -> S = fmi3Error,
        fmi3DoStep: (I, f64, f64, B, *mut B, *mut B, *mut B, *mut f64) -> S = fmi3Error,
    }
}

impl std::fmt::Debug for Fmi3Functions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fmi3Functions")
            .field("symbols", &Self::SYMBOLS.len())
            .finish_non_exhaustive()
    }
}
