//! The safe instances, FMI 2.0 ([`fmi2`]) and FMI 3.0 ([`fmi3`]) side by side,
//! each an [`FmuInstance`](crate::FmuInstance) over its raw component
//! (`crate::component`).

pub(crate) mod fmi2;
pub(crate) mod fmi3;
pub(crate) mod me;

pub use fmi2::{FmuState, Instance, LocalInstance, StatusKind};
pub use fmi3::Fmi3Instance;
pub use me::{Integrator, MeInstance, Method, MAX_EVENT_ITERATIONS};
