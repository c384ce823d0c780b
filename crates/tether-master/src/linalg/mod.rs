//! Linear algebra of the interface solve: the Jacobians, the dense LU with its
//! condition check ([`solve`]) and the sparse LU for large systems
//! ([`sparse_lu`]).

pub(crate) mod solve;
pub(crate) mod sparse_lu;
