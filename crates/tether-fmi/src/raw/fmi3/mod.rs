//! The FMI 3.0 raw layer: the C types and function table of `fmi3PlatformTypes.h` /
//! `fmi3FunctionTypes.h` (the common and co-simulation functions), and a thin owner of
//! one `fmi3Instance` whose methods are named after the C functions and go through the
//! same status check as the FMI 2.0 calls ([`check`](super::check)).
//!
//! The calls themselves are in the crate-private `component::fmi3`, one of the
//! crate's FFI modules.

#![allow(non_camel_case_types, non_snake_case, non_upper_case_globals)]

mod functions;

use std::ffi::{c_char, c_int, c_void};

pub use functions::Fmi3Functions;

/// `fmi3Instance`: the FMU's opaque instance pointer.
pub type fmi3Instance = *mut c_void;
/// `fmi3InstanceEnvironment`: the importer's pointer handed back in callbacks.
pub type fmi3InstanceEnvironment = *mut c_void;
/// `fmi3FMUState`: the FMU's opaque state pointer.
pub type fmi3FMUState = *mut c_void;
/// `fmi3ValueReference`.
pub type fmi3ValueReference = u32;
/// `fmi3Float32`.
pub type fmi3Float32 = f32;
/// `fmi3Float64`.
pub type fmi3Float64 = f64;
/// `fmi3Int8`.
pub type fmi3Int8 = i8;
/// `fmi3UInt8`.
pub type fmi3UInt8 = u8;
/// `fmi3Int16`.
pub type fmi3Int16 = i16;
/// `fmi3UInt16`.
pub type fmi3UInt16 = u16;
/// `fmi3Int32`.
pub type fmi3Int32 = i32;
/// `fmi3UInt32`.
pub type fmi3UInt32 = u32;
/// `fmi3Int64`.
pub type fmi3Int64 = i64;
/// `fmi3UInt64`.
pub type fmi3UInt64 = u64;
/// `fmi3Boolean`: C `bool`, kept as a byte so that any value the FMU writes is sound
/// (0 is false, anything else true).
pub type fmi3Boolean = u8;
/// `fmi3Char`.
pub type fmi3Char = c_char;
/// `fmi3String`.
pub type fmi3String = *const fmi3Char;
/// `fmi3Byte`.
pub type fmi3Byte = u8;
/// `fmi3Binary`.
pub type fmi3Binary = *const fmi3Byte;
/// `fmi3Status` (an `int`-sized C enum; kept as an integer so any value is sound).
pub type fmi3Status = c_int;

/// `fmi3True`.
pub const fmi3True: fmi3Boolean = 1;
/// `fmi3False`.
pub const fmi3False: fmi3Boolean = 0;
/// `fmi3OK`.
pub const fmi3OK: fmi3Status = 0;
/// `fmi3Warning`.
pub const fmi3Warning: fmi3Status = 1;
/// `fmi3Discard`.
pub const fmi3Discard: fmi3Status = 2;
/// `fmi3Error`.
pub const fmi3Error: fmi3Status = 3;
/// `fmi3Fatal`.
pub const fmi3Fatal: fmi3Status = 4;

/// `fmi3LogMessageCallback` (not variadic in FMI 3.0: the message is formatted).
pub type fmi3LogMessageCallback = Option<
    unsafe extern "C" fn(
        instanceEnvironment: fmi3InstanceEnvironment,
        status: fmi3Status,
        category: fmi3String,
        message: fmi3String,
    ),
>;

/// `fmi3IntermediateUpdateCallback` (Tether's: `intermediate_update` in the crate-private `component::fmi3`).
pub type fmi3IntermediateUpdateCallback = Option<
    unsafe extern "C" fn(
        instanceEnvironment: fmi3InstanceEnvironment,
        intermediateUpdateTime: fmi3Float64,
        intermediateVariableSetRequested: fmi3Boolean,
        intermediateVariableGetAllowed: fmi3Boolean,
        intermediateStepFinished: fmi3Boolean,
        canReturnEarly: fmi3Boolean,
        earlyReturnRequested: *mut fmi3Boolean,
        earlyReturnTime: *mut fmi3Float64,
    ),
>;
