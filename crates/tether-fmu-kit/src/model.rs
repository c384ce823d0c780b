//! The one trait a model author implements.

use crate::declaration::{Declaration, Parameters};
use crate::input::InputJet;

/// A continuous-time model ẋ = f(t, x, u), y = g(t, x, u) with parameters.
///
/// The kit owns time, states, inputs (with their derivatives) and parameter values;
/// the model only evaluates equations. The model value itself is rebuilt from the
/// parameters by [`Model::new`] whenever they change, so it can hold validated,
/// precomputed data.
pub trait Model: Sized + 'static {
    /// Names, parameters, inputs, outputs and states, in value-reference order.
    const DECLARATION: Declaration;

    /// Whether the model logs messages of its own through
    /// [`environment_logger`](crate::environment_logger). Only then does the
    /// kit put the instance's logger in scope during each FMI call (a
    /// thread-local set and reset around the call); for a model that says
    /// `false`, the default, `environment_logger` is `None`.
    const LOGS: bool = false;

    /// Builds the model from parameter values, or says which one is invalid (the kit
    /// logs the message and returns fmi2Error).
    fn new(parameters: &Parameters) -> Result<Self, String>;

    /// Initial values of the continuous states (in `DECLARATION.states` order).
    fn initial_states(&self, x: &mut [f64]);

    /// Right-hand side ẋ = f(t, x, u).
    fn derivatives(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]);

    /// Outputs y = g(t, x, u); direct feedthrough is an output that reads `u`.
    fn outputs(&self, t: f64, x: &[f64], u: &[f64], y: &mut [f64]);

    /// The `order`-th time derivatives of all outputs (order 1..=
    /// `max_output_derivative_order`), given the inputs with their derivatives.
    /// Return `false` if not provided (the default).
    fn output_derivatives(
        &self,
        _t: f64,
        _x: &[f64],
        _u: &[InputJet],
        _order: u32,
        _dy: &mut [f64],
    ) -> bool {
        false
    }

    /// Advances `x` from `t` to `t + h` exactly, with the inputs given as Taylor
    /// polynomials around `t`. Return `false` to let the kit integrate numerically
    /// (the default).
    fn exact_step(&self, _t: f64, _h: f64, _x: &mut [f64], _u: &[InputJet]) -> bool {
        false
    }

    /// The largest internal step the numerical integrator may take, if the model
    /// limits it (as a model exported with a fixed-rate solver does). `None`, the
    /// default, leaves Dop853's step to its error control.
    fn max_step(&self) -> Option<f64> {
        None
    }

    /// Whether the model asks the master to end the simulation after a step that
    /// reached `t` with states `x`. When it does, the step is kept (time and
    /// states are those at `t`), `fmi2DoStep` returns fmi2Discard and
    /// `fmi2GetBooleanStatus(fmi2Terminated)` is true from then on, as the
    /// Reference FMU `Stair` does; `fmi2GetRealStatus(fmi2LastSuccessfulTime)`
    /// is `t`. The default never asks.
    fn terminate(&self, _t: f64, _x: &[f64]) -> bool {
        false
    }

    /// What `fmi2SetFMUstate` does at the instance's time `t` (before the
    /// restore). The default, and every model but a fault-injecting one:
    /// [`Restore::Exact`].
    fn restore(&self, _t: f64) -> Restore {
        Restore::Exact
    }

    /// Whether the FMU resets every parameter to its declared start value
    /// (the values set before are lost), as FMUs exported by some modelling
    /// tools do, given the parameters as set: for conformance tests of
    /// importers. The default, and every model but such a test model:
    /// [`ParameterReset::Never`].
    fn parameter_reset(_parameters: &Parameters) -> ParameterReset {
        ParameterReset::Never
    }
}

/// When an FMU resets its parameters to their start values ([`Model::parameter_reset`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParameterReset {
    /// Never: the values set stay.
    Never,
    /// In `fmi2SetupExperiment` (FMI 2.0 only): values set before it are lost.
    AtSetupExperiment,
    /// In `fmi2ExitInitializationMode` / `fmi3ExitInitializationMode`: every
    /// value set is lost, whatever the importer's order.
    AtExitInitialization,
}

/// How `fmi2SetFMUstate` restores a state ([`Model::restore`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Restore {
    /// The saved state, exactly (FMI 2.0).
    Exact,
    /// Everything but the continuous states, which stay as they are: the
    /// call returns fmi2OK, the time goes back, the states do not.
    KeepStates,
}
