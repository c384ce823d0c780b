//! The co-simulation master.
