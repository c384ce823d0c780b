//! Single-mass oscillator: m ẍ = F + F_ext − c x − d v.
//!
//! Outputs position `x`, velocity `v` and acceleration `a` (direct feedthrough of the
//! forces `F` and `F_ext`), with output derivatives up to order 2. With
//! `exact = true` a step is the matrix exponential of the system augmented with the
//! input polynomial, exact for inputs of degree ≤ 2. Two force inputs let a
//! constraint drive one (`F`) while a signal connection drives the other (`F_ext`,
//! e.g. from a controller); the model only sees their sum.
//!
//! The model is the crate `oscillator-model` (`model/`), which the `faults` and
//! `quirks` FMUs share; this crate exports it as an FMU.

pub use oscillator_model::{declare, Oscillator};
use tether_fmu_kit::export_fmu;

export_fmu!(Oscillator);
