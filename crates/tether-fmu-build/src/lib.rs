//! Build and package FMUs.
