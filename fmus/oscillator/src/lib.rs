//! Single-mass oscillator.
