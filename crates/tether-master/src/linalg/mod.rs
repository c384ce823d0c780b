//! Linear algebra of the interface solve: the Jacobians and the solver with its
//! condition check ([`solve`]), the dense LU kernels ([`lu`]) and the sparse LU
//! for large systems ([`sparse_lu`]).

mod lu;
pub(crate) mod solve;
pub(crate) mod sparse_lu;
