//! The FFI layer: one owner per FMU instance whose methods are the C functions
//! under their own names, FMI 2.0 ([`fmi2`]) and FMI 3.0 ([`fmi3`]) side by side,
//! over the C types of [`crate::raw`]. Every `unsafe` call into an FMU is here;
//! each goes through the one status check ([`crate::raw::check`]).

#![allow(non_snake_case)]

pub(crate) mod fmi2;
pub(crate) mod fmi3;

use std::ffi::CString;

use crate::error::{Error, Result};

/// `texts` as C strings (log categories, String values); one with a NUL byte
/// is an error naming `function`, the instance and `what` it is.
fn c_strings(
    texts: &[&str],
    what: &str,
    function: &'static str,
    instance: &str,
) -> Result<Vec<CString>> {
    texts
        .iter()
        .map(|t| CString::new(*t))
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| Error::InvalidArgument {
            function,
            instance: instance.to_string(),
            message: format!("a {what} contains a NUL byte"),
        })
}
