//! The contract of a macro step: where it is on the grid ([`StepAt`], with
//! its polynomials' [`Degree`]) and [`MacroStep`], the step every coupling
//! method takes on the [`System`], with the state it carries between steps
//! ([`MethodState`]).

use crate::polynomial::Past;
use crate::stats::{Lap, RunStats};
use crate::step_control::StepControl;
use crate::system::System;
use crate::MasterError;

/// Where a macro step T_N → T_{N+1} is on the grid.
#[derive(Debug, Clone, Copy)]
pub(crate) struct StepAt {
    /// N, the index of the step's start.
    pub n: u64,
    /// T_N.
    pub t: f64,
    /// H.
    pub h: f64,
    /// T_{N+1} (from N + 1, not T_N + H, on the uniform grid).
    pub t_next: f64,
    /// The two step sizes before this one on a variable grid (adaptive
    /// steps); `None` on the uniform grid.
    pub past: Past,
    /// The degrees of the step's polynomials.
    pub degree: Degree,
}

/// The degrees of a step's polynomials: k, or fewer in start-up, where only
/// N + 1 points of history exist at T_N (docs/algorithm.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Degree {
    /// The predictor's extrapolation through u_N, u_{N−1}, …: min(k, N).
    pub predictor: usize,
    /// The corrector's interpolation through u_{N+1}, u_N, …: min(k, N + 1).
    pub corrector: usize,
}

impl Degree {
    /// The degrees of step N with polynomials of degree `k`.
    pub fn at(n: u64, k: usize) -> Degree {
        let n = usize::try_from(n).unwrap_or(usize::MAX);
        Degree {
            predictor: k.min(n),
            corrector: k.min(n.saturating_add(1)),
        }
    }
}

/// A method's own state between steps, as [`MacroStep::save`] made it.
pub(crate) type MethodState = Box<dyn std::any::Any + Send + Sync>;

/// One macro step of a coupling method: predictor/corrector or explicit.
pub(crate) trait MacroStep: Send {
    /// Advance every instance and the unknowns from T_N to T_{N+1}, leave
    /// u_{N+1} at the head of the history and the accepted outputs read;
    /// count solves in `stats`, split the phases on `lap`. With adaptive
    /// steps it returns the step's error norm; a step whose norm exceeds 1
    /// is rolled back instead (every instance restored to T_N, the history
    /// unchanged).
    fn step(
        &mut self,
        system: &mut System,
        at: StepAt,
        stats: &mut RunStats,
        lap: &mut Lap,
    ) -> Result<Option<f64>, MasterError>;

    /// Turn on adaptive steps: the error estimate with these tolerances,
    /// every instance saved each step so a rejected step can be rolled back.
    /// Called once the initial outputs are read. Only the predictor/corrector
    /// method estimates errors.
    fn control_steps(&mut self, _system: &System, _control: &StepControl) -> bool {
        false
    }

    /// The method's own state carried from one step to the next (Jacobian
    /// reuse, the error estimate's scales), for the master's saved state.
    fn save(&self) -> MethodState {
        Box::new(())
    }

    /// Back to a state of [`save`](Self::save).
    fn restore(&mut self, _state: &MethodState) {}
}
