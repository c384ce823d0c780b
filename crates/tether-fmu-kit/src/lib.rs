//! FMU export kit.
