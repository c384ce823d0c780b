//! The coupling methods, each a [`MacroStep`](step::MacroStep) on the
//! [`System`](crate::system::System) ([`step`] is the contract): the
//! predictor/corrector step of the paper ([`predictor_corrector`]) with its
//! error estimate for adaptive steps ([`error_estimate`]) and Jacobian reuse
//! ([`jacobian_reuse`]), the explicit baseline ([`explicit`]), and how the
//! perturbed runs of a step are executed ([`runs`], [`threads`]). Signal
//! connections and their loop solver are [`crate::signals`].

pub(crate) mod error_estimate;
pub(crate) mod explicit;
pub(crate) mod jacobian_reuse;
pub(crate) mod predictor_corrector;
pub(crate) mod runs;
pub(crate) mod step;
pub(crate) mod threads;
