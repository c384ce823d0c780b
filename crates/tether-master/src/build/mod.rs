//! Building the coupled [`System`](system::System) from a system file: the
//! constraints, joints and coupling variables resolved against the FMUs'
//! variables into rows and unknowns ([`resolve`]), the instances instantiated
//! and initialised ([`system`], which also holds [`MacroStep`](system::MacroStep),
//! the step every coupling method in [`crate::algorithm`] takes on it), and
//! the consistent initial multipliers from direct feedthrough ([`feedthrough`]).

pub(crate) mod feedthrough;
pub(crate) mod resolve;
pub(crate) mod system;
