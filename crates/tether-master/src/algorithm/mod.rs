//! The coupling methods, each a [`MacroStep`](step::MacroStep) on the
//! [`System`](crate::system::System) ([`step`] is the contract): the
//! predictor/corrector step of the paper ([`predictor_corrector`]) with its
//! error estimate for adaptive steps ([`error_estimate`]) and Jacobian reuse
//! ([`jacobian_reuse`]) and the explicit baseline ([`explicit`]). How the
//! runs of a step are made, on the main thread or on worker threads, is
//! [`crate::runs`]; signal connections and their loop solver are
//! [`crate::signals`].

pub(crate) mod error_estimate;
pub(crate) mod explicit;
pub(crate) mod jacobian_reuse;
pub(crate) mod predictor_corrector;
pub(crate) mod step;
