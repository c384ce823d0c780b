//! Shared helpers for the integration tests in tests/.

pub mod faulty;
pub mod fmi;
pub mod fmpy;
pub mod multibody;
pub mod reference;
