//! Write FMI 2.0 co-simulation FMUs in Rust.
//!
//! A model implements [`Model`] (a `const` [`Declaration`] and its equations) and
//! calls [`export_fmu!`] once; the kit provides every `fmi2*` function of the
//! co-simulation interface, the state machine, input interpolation, integration
//! (Dop853), FMU states and their serialization, logging, and the generated
//! `modelDescription.xml` (exported as `tether_fmu_kit_model_description`). A model
//! that declares [`Model::LOGS`] logs messages of its own through
//! [`environment_logger`].
//! See `docs/fmu-kit.md`.

mod access;
pub mod declaration;
pub mod ffi;
pub mod input;
pub mod instance;
mod integrate;
pub mod machine;
pub mod marker;
pub mod model;
pub mod snapshot;
pub mod xml;

pub use declaration::{
    Boolean, Capabilities, Declaration, DefaultExperiment, Integer, Output, Parameters, Real, State,
};
pub use ffi::{environment_logger, EnvironmentLogger};
pub use input::InputJet;
pub use marker::MarkerKinematics;
pub use model::Model;

/// Exports `$model` (a type implementing [`Model`]) as an FMI 2.0 co-simulation FMU:
/// generates every `#[no_mangle] extern "C"` fmi2 function of the co-simulation
/// interface plus `tether_fmu_kit_model_description`. Use once per cdylib crate.
#[macro_export]
macro_rules! export_fmu {
    ($model:ty) => {
        #[allow(non_snake_case, clippy::missing_safety_doc)]
        mod __tether_fmu_exports {
            use super::*;
            use std::ffi::{c_char, c_int};
            use $crate::ffi as k;
            use $crate::ffi::{
                Fmi2Boolean as B, Fmi2Component as C, Fmi2FmuState as S, Fmi2Status as St,
                Fmi2String as Str, Fmi2ValueReference as Vr,
            };
            type M = $model;

            /// The generated modelDescription.xml (NUL-terminated, static), or null if
            /// the declaration is invalid.
            #[unsafe(no_mangle)]
            pub extern "C" fn tether_fmu_kit_model_description() -> *const c_char {
                static XML: std::sync::OnceLock<Option<std::ffi::CString>> =
                    std::sync::OnceLock::new();
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
                unsafe { k::instantiate::<M>(name, fmu_type, guid, functions, logging_on) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2FreeInstance(c: C) {
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
            pub unsafe extern "C" fn fmi2GetInteger(
                c: C,
                vr: *const Vr,
                n: usize,
                v: *mut c_int,
            ) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::get_integer::<M>(c, vr, n, v) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetBoolean(
                c: C,
                vr: *const Vr,
                n: usize,
                v: *mut B,
            ) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::get_boolean::<M>(c, vr, n, v) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetString(
                c: C,
                vr: *const Vr,
                n: usize,
                v: *mut Str,
            ) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::get_string::<M>(c, vr, n, v) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetReal(
                c: C,
                vr: *const Vr,
                n: usize,
                v: *const f64,
            ) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::set_real::<M>(c, vr, n, v) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetInteger(
                c: C,
                vr: *const Vr,
                n: usize,
                v: *const c_int,
            ) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::set_integer::<M>(c, vr, n, v) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetBoolean(
                c: C,
                vr: *const Vr,
                n: usize,
                v: *const B,
            ) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::set_boolean::<M>(c, vr, n, v) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetString(
                c: C,
                vr: *const Vr,
                n: usize,
                v: *const Str,
            ) -> St {
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
            pub unsafe extern "C" fn fmi2SerializedFMUstateSize(
                c: C,
                s: S,
                size: *mut usize,
            ) -> St {
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
    };
}

#[cfg(test)]
mod tests;
