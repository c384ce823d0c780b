//! A Tether system exported as one FMI 2.0 co-simulation FMU
//! (`tether fmu export`, docs/fmu-export.md).
//!
//! The cdylib is the FMU's binary: its `fmi2*` functions ([`ffi`]) run
//! [`tether_master::Simulation`] on the system file in the unpacked FMU's
//! `resources/`, whose member FMUs are there too ([`runtime`]). The rlib
//! gives the CLI and the Python package the same model description and
//! GUID ([`description`]) and writes the `.fmu` ([`package`]).

pub mod description;
pub mod ffi;
pub mod ffi3;
pub mod package;
pub mod runtime;

/// The system file's name inside the FMU's `resources/`.
pub const SYSTEM_FILE: &str = "system.toml";
