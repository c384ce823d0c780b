//! The FFI layer: one owner per FMU instance whose methods are the C functions
//! under their own names, FMI 2.0 ([`fmi2`]) and FMI 3.0 ([`fmi3`]) side by side,
//! over the C types of [`crate::raw`]. Every `unsafe` call into an FMU is here;
//! each goes through the one status check ([`crate::raw::check`]).

#![allow(non_snake_case)]

pub(crate) mod fmi2;
pub(crate) mod fmi3;

use std::ffi::CString;

use crate::error::{Error, Result};

/// The log categories of `fmi2SetDebugLogging` / `fmi3SetDebugLogging` as C
/// strings; one with a NUL byte is an error naming `function` and the instance.
fn categories(categories: &[&str], function: &'static str, instance: &str) -> Result<Vec<CString>> {
    categories
        .iter()
        .map(|c| CString::new(*c))
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| Error::InvalidArgument {
            function,
            instance: instance.to_string(),
            message: "a category name contains a NUL byte".into(),
        })
}
