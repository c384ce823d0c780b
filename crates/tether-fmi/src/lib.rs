//! FMI 2.0 co-simulation import.
