//! The function-pointer tables of model exchange, FMI 2.0 ([`Fmi2MeFunctions`]) and
//! FMI 3.0 ([`Fmi3MeFunctions`]): the functions a model-exchange instance calls
//! besides the common ones of [`Fmi2Functions`](super::Fmi2Functions) and
//! [`Fmi3Functions`](super::fmi3::Fmi3Functions). A library that lacks one of them
//! loads as before (co-simulation needs none of them); a model-exchange instance of
//! it is refused, naming the first missing function.

use std::path::Path;

use super::fmi3::*;
use super::*;
use crate::error::Error;

macro_rules! me_functions {
    ($table:ident, $standard:literal, $($name:ident: $ty:ty,)*) => {
        #[doc = concat!("The model-exchange functions of ", $standard, ", resolved from the FMU's")]
        /// shared library. Field names are the C symbol names.
        #[derive(Clone, Copy)]
        pub struct $table {
            $(
                #[doc = concat!("`", stringify!($name), "`.")]
                pub $name: $ty,
            )*
        }

        impl $table {
            /// The C symbol names, in table order.
            pub const SYMBOLS: &'static [&'static str] = &[$(stringify!($name)),*];

            /// Resolves every function; `Err` names the first one that is missing.
            pub(crate) fn resolve(
                lib: &libloading::Library,
            ) -> std::result::Result<Self, &'static str> {
                Ok($table {
                    $(
                        $name: {
                            // SAFETY: the symbol is looked up by its standard name and given
                            // the signature the standard's function-types header declares
                            // for that name; an FMU exporting another signature under a
                            // standard name violates the standard, which no importer can
                            // detect. The pointer is only used while `lib` stays loaded
                            // (the `Library` owning it is held in an `Arc` by every
                            // instance).
                            let symbol = unsafe { lib.get::<$ty>(stringify!($name)) };
                            *symbol.map_err(|_| stringify!($name))?
                        },
                    )*
                })
            }
        }

        impl std::fmt::Debug for $table {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.debug_struct(stringify!($table))
                    .field("symbols", &Self::SYMBOLS.len())
                    .finish_non_exhaustive()
            }
        }
    };
}

/// `fmi2EventInfo`: what `fmi2NewDiscreteStates` reports.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct fmi2EventInfo {
    /// Another round of `fmi2NewDiscreteStates` is needed.
    pub newDiscreteStatesNeeded: fmi2Boolean,
    /// The FMU asks to end the simulation.
    pub terminateSimulation: fmi2Boolean,
    /// The nominals of the continuous states changed.
    pub nominalsOfContinuousStatesChanged: fmi2Boolean,
    /// The values of the continuous states changed.
    pub valuesOfContinuousStatesChanged: fmi2Boolean,
    /// `nextEventTime` holds the next time event.
    pub nextEventTimeDefined: fmi2Boolean,
    /// The next time event, if defined.
    pub nextEventTime: fmi2Real,
}

type C = fmi2Component;
type I = fmi3Instance;
type B3 = fmi3Boolean;
type S3 = fmi3Status;

me_functions! {
    Fmi2MeFunctions, "FMI 2.0",
    fmi2EnterEventMode: unsafe extern "C" fn(C) -> fmi2Status,
    fmi2NewDiscreteStates: unsafe extern "C" fn(C, *mut fmi2EventInfo) -> fmi2Status,
    fmi2EnterContinuousTimeMode: unsafe extern "C" fn(C) -> fmi2Status,
    fmi2CompletedIntegratorStep: unsafe extern "C" fn(C, fmi2Boolean, *mut fmi2Boolean, *mut fmi2Boolean) -> fmi2Status,
    fmi2SetTime: unsafe extern "C" fn(C, fmi2Real) -> fmi2Status,
    fmi2SetContinuousStates: unsafe extern "C" fn(C, *const fmi2Real, usize) -> fmi2Status,
    fmi2GetDerivatives: unsafe extern "C" fn(C, *mut fmi2Real, usize) -> fmi2Status,
    fmi2GetEventIndicators: unsafe extern "C" fn(C, *mut fmi2Real, usize) -> fmi2Status,
    fmi2GetContinuousStates: unsafe extern "C" fn(C, *mut fmi2Real, usize) -> fmi2Status,
    fmi2GetNominalsOfContinuousStates: unsafe extern "C" fn(C, *mut fmi2Real, usize) -> fmi2Status,
}

me_functions! {
    Fmi3MeFunctions, "FMI 3.0",
    fmi3InstantiateModelExchange: unsafe extern "C" fn(
        fmi3String,
        fmi3String,
        fmi3String,
        B3,
        B3,
        fmi3InstanceEnvironment,
        fmi3LogMessageCallback,
    ) -> fmi3Instance,
    fmi3EnterEventMode: unsafe extern "C" fn(I) -> S3,
    fmi3UpdateDiscreteStates: unsafe extern "C" fn(I, *mut B3, *mut B3, *mut B3, *mut B3, *mut B3, *mut f64) -> S3,
    fmi3EnterContinuousTimeMode: unsafe extern "C" fn(I) -> S3,
    fmi3CompletedIntegratorStep: unsafe extern "C" fn(I, B3, *mut B3, *mut B3) -> S3,
    fmi3SetTime: unsafe extern "C" fn(I, f64) -> S3,
    fmi3SetContinuousStates: unsafe extern "C" fn(I, *const f64, usize) -> S3,
    fmi3GetContinuousStateDerivatives: unsafe extern "C" fn(I, *mut f64, usize) -> S3,
    fmi3GetEventIndicators: unsafe extern "C" fn(I, *mut f64, usize) -> S3,
    fmi3GetContinuousStates: unsafe extern "C" fn(I, *mut f64, usize) -> S3,
    fmi3GetNominalsOfContinuousStates: unsafe extern "C" fn(I, *mut f64, usize) -> S3,
    fmi3GetNumberOfEventIndicators: unsafe extern "C" fn(I, *mut usize) -> S3,
    fmi3GetNumberOfContinuousStates: unsafe extern "C" fn(I, *mut usize) -> S3,
    fmi3GetDirectionalDerivative: unsafe extern "C" fn(
        I,
        *const fmi3ValueReference,
        usize,
        *const fmi3ValueReference,
        usize,
        *const f64,
        usize,
        *mut f64,
        usize,
    ) -> S3,
}

/// The error for a model-exchange instance of a library without `symbol`.
pub(crate) fn missing(path: &Path, symbol: &'static str) -> Error {
    Error::MissingSymbol {
        library: path.to_owned(),
        symbol,
    }
}
