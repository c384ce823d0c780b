//! The FFI layer: one owner per FMU instance whose methods are the C functions
//! under their own names, FMI 2.0 ([`fmi2`]) and FMI 3.0 ([`fmi3`]) side by side,
//! over the C types of [`crate::raw`]. Every `unsafe` call into an FMU is here;
//! each goes through the one status check ([`crate::raw::check`]).

#![allow(non_snake_case)]

pub(crate) mod fmi2;
pub(crate) mod fmi3;
