//! Write FMI 2.0 and FMI 3.0 co-simulation FMUs in Rust.
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
mod me;
pub mod model;
pub mod snapshot;
pub mod xml;

pub use declaration::{
    Boolean, Capabilities, Declaration, DefaultExperiment, Integer, Output, Parameters, Real, State,
};
pub use ffi::{environment_logger, EnvironmentLogger};
pub use input::InputJet;
pub use marker::MarkerKinematics;
pub use model::{Model, ParameterReset};

/// Exports `$model` (a type implementing [`Model`]) as an FMI 2.0 and an FMI 3.0
/// co-simulation FMU from one library: generates every `#[no_mangle] extern "C"`
/// fmi2 function of the co-simulation and model-exchange interfaces, every fmi3
/// function of the common, co-simulation and model-exchange interfaces (model
/// exchange instantiates only for a model whose declaration sets
/// [`model_exchange`](declaration::Declaration::model_exchange)), and `tether_fmu_kit_model_description` and
/// `tether_fmu_kit_model_description_fmi3` (the packager puts one of the two in the
/// archive). Use once per cdylib crate.
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

            // Model exchange: refused unless the instance was made for it
            // (fmi2Instantiate with fmi2ModelExchange, for a model that declares it).
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetTime(c: C, t: f64) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::me::set_time::<M>(c, t) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2SetContinuousStates(c: C, x: *const f64, n: usize) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::me::set_continuous_states::<M>(c, x, n) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetContinuousStates(c: C, x: *mut f64, n: usize) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::me::get_continuous_states::<M>(c, x, n) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetDerivatives(c: C, dx: *mut f64, n: usize) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::me::get_derivatives::<M>(c, dx, n) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetEventIndicators(c: C, z: *mut f64, n: usize) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::me::get_event_indicators::<M>(c, z, n) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2GetNominalsOfContinuousStates(
                c: C,
                v: *mut f64,
                n: usize,
            ) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::me::get_nominals::<M>(c, v, n) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2EnterEventMode(c: C) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::me::change_mode::<M>(c, "fmi2EnterEventMode") }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2NewDiscreteStates(
                c: C,
                info: *mut k::me::Fmi2EventInfo,
            ) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::me::new_discrete_states::<M>(c, info) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2EnterContinuousTimeMode(c: C) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::me::change_mode::<M>(c, "fmi2EnterContinuousTimeMode") }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi2CompletedIntegratorStep(
                c: C,
                _no_set_fmu_state_prior: B,
                enter_event_mode: *mut B,
                terminate: *mut B,
            ) -> St {
                // SAFETY: the FMI 2.0 contract; the kit checks every pointer for null.
                unsafe { k::me::completed_integrator_step::<M, B>(c, enter_event_mode, terminate) }
            }
        }

        #[allow(non_snake_case, clippy::missing_safety_doc, clippy::too_many_arguments)]
        mod __tether_fmu_exports_fmi3 {
            use super::*;
            use std::ffi::{c_char, c_void};
            use $crate::ffi as k;
            use $crate::ffi::fmi3 as k3;
            use $crate::ffi::fmi3::{Fmi3Boolean as B, Fmi3Status as St, Fmi3String as Str};
            type C = *mut c_void;
            type S = *mut c_void;
            type Vr = *const k3::Fmi3ValueReference;
            type M = $model;

            /// The generated FMI 3.0 modelDescription.xml (NUL-terminated, static), or
            /// null if the declaration is invalid.
            #[unsafe(no_mangle)]
            pub extern "C" fn tether_fmu_kit_model_description_fmi3() -> *const c_char {
                static XML: std::sync::OnceLock<Option<std::ffi::CString>> =
                    std::sync::OnceLock::new();
                k::model_description_fmi3::<M>(&XML)
            }

            #[unsafe(no_mangle)]
            pub extern "C" fn fmi3GetVersion() -> *const c_char {
                k3::get_version()
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3SetDebugLogging(
                c: C,
                on: B,
                n: usize,
                categories: *const Str,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::set_debug_logging::<M>(c, i32::from(on), n, categories) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3InstantiateCoSimulation(
                name: Str,
                token: Str,
                _resources: Str,
                _visible: B,
                logging_on: B,
                _event_mode_used: B,
                _early_return_allowed: B,
                _required_intermediate: Vr,
                _n_required_intermediate: usize,
                environment: *mut c_void,
                log_message: k3::Fmi3LogMessageCallback,
                intermediate_update: k3::Fmi3IntermediateUpdateCallback,
            ) -> C {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe {
                    k3::instantiate_co_simulation::<M>(
                        name,
                        token,
                        logging_on,
                        environment,
                        log_message,
                        intermediate_update,
                    )
                }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3FreeInstance(c: C) {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::free_instance::<M>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3EnterInitializationMode(
                c: C,
                tol_defined: B,
                tol: f64,
                start: f64,
                stop_defined: B,
                stop: f64,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe {
                    k3::enter_initialization_mode::<M>(
                        c,
                        tol_defined,
                        tol,
                        start,
                        stop_defined,
                        stop,
                    )
                }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3ExitInitializationMode(c: C) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::exit_initialization_mode::<M>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3Terminate(c: C) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::terminate::<M>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3Reset(c: C) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::reset::<M>(c) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3GetFloat64(
                c: C,
                vr: Vr,
                n: usize,
                v: *mut f64,
                nv: usize,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k3::get_float64::<M>(c, vr, n, v, nv) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3SetFloat64(
                c: C,
                vr: Vr,
                n: usize,
                v: *const f64,
                nv: usize,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k3::set_float64::<M>(c, vr, n, v, nv) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3GetInt32(
                c: C,
                vr: Vr,
                n: usize,
                v: *mut i32,
                nv: usize,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k3::get_int32::<M>(c, vr, n, v, nv) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3SetInt32(
                c: C,
                vr: Vr,
                n: usize,
                v: *const i32,
                nv: usize,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k3::set_int32::<M>(c, vr, n, v, nv) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3GetBoolean(
                c: C,
                vr: Vr,
                n: usize,
                v: *mut B,
                nv: usize,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k3::get_boolean::<M>(c, vr, n, v, nv) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3SetBoolean(
                c: C,
                vr: Vr,
                n: usize,
                v: *const B,
                nv: usize,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k3::set_boolean::<M>(c, vr, n, v, nv) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3GetFMUState(c: C, s: *mut S) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::get_fmu_state::<M>(c, s) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3SetFMUState(c: C, s: S) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::set_fmu_state::<M>(c, s) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3FreeFMUState(c: C, s: *mut S) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::free_fmu_state::<M>(c, s) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3SerializedFMUStateSize(
                c: C,
                s: S,
                size: *mut usize,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::serialized_fmu_state_size::<M>(c, s, size) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3SerializeFMUState(
                c: C,
                s: S,
                bytes: *mut u8,
                size: usize,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::serialize_fmu_state::<M>(c, s, bytes.cast(), size) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3DeserializeFMUState(
                c: C,
                bytes: *const u8,
                size: usize,
                s: *mut S,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::deserialize_fmu_state::<M>(c, bytes.cast(), size, s) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3GetOutputDerivatives(
                c: C,
                vr: Vr,
                n: usize,
                orders: *const i32,
                v: *mut f64,
                nv: usize,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k3::get_output_derivatives::<M>(c, vr, n, orders, v, nv) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3DoStep(
                c: C,
                t: f64,
                h: f64,
                _no_set_fmu_state_prior: B,
                event_handling_needed: *mut B,
                terminate_simulation: *mut B,
                early_return: *mut B,
                last_successful_time: *mut f64,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe {
                    k3::do_step::<M>(
                        c,
                        t,
                        h,
                        event_handling_needed,
                        terminate_simulation,
                        early_return,
                        last_successful_time,
                    )
                }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3EnterStepMode(c: C) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k3::enter_step_mode::<M>(c) }
            }

            $crate::fmi3_unsupported_but_model_exchange! { k3::unsupported::<M>; }

            // Model exchange: refused unless the instance was made for it
            // (fmi3InstantiateModelExchange, for a model that declares it).
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3InstantiateModelExchange(
                name: Str,
                token: Str,
                _resources: Str,
                _visible: B,
                logging_on: B,
                environment: *mut c_void,
                log_message: k3::Fmi3LogMessageCallback,
            ) -> C {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe {
                    k3::instantiate_model_exchange::<M>(
                        name,
                        token,
                        logging_on,
                        environment,
                        log_message,
                    )
                }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3SetTime(c: C, t: f64) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::me::set_time::<M>(c, t) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3SetContinuousStates(c: C, x: *const f64, n: usize) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::me::set_continuous_states::<M>(c, x, n) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3GetContinuousStates(c: C, x: *mut f64, n: usize) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::me::get_continuous_states::<M>(c, x, n) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3GetContinuousStateDerivatives(
                c: C,
                dx: *mut f64,
                n: usize,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::me::get_derivatives::<M>(c, dx, n) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3GetEventIndicators(c: C, z: *mut f64, n: usize) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::me::get_event_indicators::<M>(c, z, n) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3GetNominalsOfContinuousStates(
                c: C,
                v: *mut f64,
                n: usize,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::me::get_nominals::<M>(c, v, n) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3GetNumberOfContinuousStates(c: C, n: *mut usize) -> St {
                let states = <M as $crate::Model>::DECLARATION.states.len();
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::me::get_number::<M>(c, "fmi3GetNumberOfContinuousStates", n, states) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3GetNumberOfEventIndicators(c: C, n: *mut usize) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::me::get_number::<M>(c, "fmi3GetNumberOfEventIndicators", n, 0) }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3EnterEventMode(c: C) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::me::change_mode::<M>(c, "fmi3EnterEventMode") }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3UpdateDiscreteStates(
                c: C,
                needs_update: *mut B,
                terminate: *mut B,
                nominals_changed: *mut B,
                values_changed: *mut B,
                next_event_time_defined: *mut B,
                next_event_time: *mut f64,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe {
                    k::me::update_discrete_states::<M>(
                        c,
                        needs_update,
                        terminate,
                        nominals_changed,
                        values_changed,
                        next_event_time_defined,
                        next_event_time,
                    )
                }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3EnterContinuousTimeMode(c: C) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::me::change_mode::<M>(c, "fmi3EnterContinuousTimeMode") }
            }
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn fmi3CompletedIntegratorStep(
                c: C,
                _no_set_fmu_state_prior: B,
                enter_event_mode: *mut B,
                terminate: *mut B,
            ) -> St {
                // SAFETY: the FMI 3.0 contract; the kit checks every pointer for null.
                unsafe { k::me::completed_integrator_step::<M, B>(c, enter_event_mode, terminate) }
            }

            // Scheduled execution is not offered: no instance.
            #[unsafe(no_mangle)]
            pub extern "C" fn fmi3InstantiateScheduledExecution(
                _name: Str,
                _token: Str,
                _resources: Str,
                _visible: B,
                _logging_on: B,
                _environment: *mut c_void,
                _log_message: k3::Fmi3LogMessageCallback,
                _clock_update: *mut c_void,
                _lock_preemption: *mut c_void,
                _unlock_preemption: *mut c_void,
            ) -> C {
                std::ptr::null_mut()
            }
        }
    };
}

/// The FMI 3.0 functions that a Float64-only co-simulation FMU without event
/// mode, clocks or derivatives refuses: one list for the kit's [`export_fmu!`]
/// and for the runtime of an exported Tether system (tether-fmu-export), which
/// names the functions it refuses besides these after the `;`. Each becomes a
/// `#[no_mangle]` function with its C signature that returns `$refuse(c,
/// "fmi3Name")`; `C`, `St`, `Vr`, `B` and `Str` are the caller's FMI 3.0 types.
#[doc(hidden)]
#[macro_export]
macro_rules! fmi3_unsupported {
    ($refuse:path; $($name:ident($($arg:ty),*);)*) => {
        $crate::fmi3_unsupported_but_model_exchange! {
            $refuse;
            $($name($($arg),*);)*
            fmi3EnterEventMode();
            fmi3UpdateDiscreteStates(*mut B, *mut B, *mut B, *mut B, *mut B, *mut f64);
            fmi3EnterContinuousTimeMode();
            fmi3CompletedIntegratorStep(B, *mut B, *mut B);
            fmi3SetTime(f64);
            fmi3SetContinuousStates(*const f64, usize);
            fmi3GetContinuousStateDerivatives(*mut f64, usize);
            fmi3GetEventIndicators(*mut f64, usize);
            fmi3GetContinuousStates(*mut f64, usize);
            fmi3GetNominalsOfContinuousStates(*mut f64, usize);
            fmi3GetNumberOfEventIndicators(*mut usize);
            fmi3GetNumberOfContinuousStates(*mut usize);
        }
    };
}

/// [`fmi3_unsupported!`] without the model-exchange functions (fmi3SetTime,
/// fmi3EnterEventMode, …), which the kit's [`export_fmu!`] implements.
#[doc(hidden)]
#[macro_export]
macro_rules! fmi3_unsupported_but_model_exchange {
    ($refuse:path; $($name:ident($($arg:ty),*);)*) => {
        $crate::__fmi3_refused! {
            $refuse;
            $($name($($arg),*);)*
            fmi3EnterConfigurationMode();
            fmi3ExitConfigurationMode();
            fmi3EvaluateDiscreteStates();
            fmi3GetFloat32(Vr, usize, *mut f32, usize);
            fmi3GetInt8(Vr, usize, *mut i8, usize);
            fmi3GetUInt8(Vr, usize, *mut u8, usize);
            fmi3GetInt16(Vr, usize, *mut i16, usize);
            fmi3GetUInt16(Vr, usize, *mut u16, usize);
            fmi3GetUInt32(Vr, usize, *mut u32, usize);
            fmi3GetInt64(Vr, usize, *mut i64, usize);
            fmi3GetUInt64(Vr, usize, *mut u64, usize);
            fmi3GetString(Vr, usize, *mut Str, usize);
            fmi3GetBinary(Vr, usize, *mut usize, *mut *const u8, usize);
            fmi3GetClock(Vr, usize, *mut B);
            fmi3SetFloat32(Vr, usize, *const f32, usize);
            fmi3SetInt8(Vr, usize, *const i8, usize);
            fmi3SetUInt8(Vr, usize, *const u8, usize);
            fmi3SetInt16(Vr, usize, *const i16, usize);
            fmi3SetUInt16(Vr, usize, *const u16, usize);
            fmi3SetUInt32(Vr, usize, *const u32, usize);
            fmi3SetInt64(Vr, usize, *const i64, usize);
            fmi3SetUInt64(Vr, usize, *const u64, usize);
            fmi3SetString(Vr, usize, *const Str, usize);
            fmi3SetBinary(Vr, usize, *const usize, *const *const u8, usize);
            fmi3SetClock(Vr, usize, *const B);
            fmi3GetNumberOfVariableDependencies(u32, *mut usize);
            fmi3GetVariableDependencies(u32, *mut usize, *mut u32, *mut usize, *mut i32, usize);
            fmi3GetDirectionalDerivative(Vr, usize, Vr, usize, *const f64, usize, *mut f64, usize);
            fmi3GetAdjointDerivative(Vr, usize, Vr, usize, *const f64, usize, *mut f64, usize);
            fmi3GetIntervalDecimal(Vr, usize, *mut f64, *mut i32);
            fmi3GetIntervalFraction(Vr, usize, *mut u64, *mut u64, *mut i32);
            fmi3GetShiftDecimal(Vr, usize, *mut f64);
            fmi3GetShiftFraction(Vr, usize, *mut u64, *mut u64);
            fmi3SetIntervalDecimal(Vr, usize, *const f64);
            fmi3SetIntervalFraction(Vr, usize, *const u64, *const u64);
            fmi3SetShiftDecimal(Vr, usize, *const f64);
            fmi3SetShiftFraction(Vr, usize, *const u64, *const u64);
            fmi3ActivateModelPartition(u32, f64);
        }
    };
}

/// The functions of [`fmi3_unsupported!`], each refused by `$refuse`.
#[doc(hidden)]
#[macro_export]
macro_rules! __fmi3_refused {
    ($refuse:path; $($name:ident($($arg:ty),*);)*) => {
        $(
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn $name(c: C, $(_: $arg),*) -> St {
                // SAFETY: the FMI 3.0 contract; only `c` is used, checked for null.
                unsafe { $refuse(c, stringify!($name)) }
            }
        )*
    };
}

#[cfg(test)]
mod tests;
