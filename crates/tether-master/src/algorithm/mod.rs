//! The coupling methods, each a [`MacroStep`](crate::build::system::MacroStep)
//! on the [`System`](crate::build::system::System): the predictor/corrector
//! step of the paper ([`predictor_corrector`]) with its error estimate for
//! adaptive steps ([`error_estimate`]) and Jacobian reuse ([`jacobian_reuse`]),
//! the explicit baseline ([`explicit`]), signal connections ([`signals`]), and
//! how the perturbed runs of a step are executed ([`runs`], [`threads`]).

pub(crate) mod error_estimate;
pub(crate) mod explicit;
pub(crate) mod jacobian_reuse;
pub(crate) mod predictor_corrector;
pub(crate) mod runs;
pub(crate) mod signals;
pub(crate) mod threads;
