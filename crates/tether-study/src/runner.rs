//! One coupled run, kept in memory, and how it ended.

use tether_master::{MasterError, MemoryRecorder, ResidualLimit, Simulation, SystemSpec};

use crate::Table;

/// How a run ended.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Reached the stop time.
    Completed,
    /// Stopped by the master's divergence check (a non-finite value or one
    /// beyond `divergence_factor` times its start magnitude); the message.
    Diverged(String),
    /// Any other error: setup, singular Jacobian, an FMU call; the message.
    Failed(String),
}

impl Outcome {
    /// `completed`, `diverged` or `failed`.
    pub fn word(&self) -> &'static str {
        match self {
            Outcome::Completed => "completed",
            Outcome::Diverged(_) => "diverged",
            Outcome::Failed(_) => "failed",
        }
    }

    /// The error message, if the run stopped early.
    pub fn message(&self) -> Option<&str> {
        match self {
            Outcome::Completed => None,
            Outcome::Diverged(m) | Outcome::Failed(m) => Some(m),
        }
    }
}

/// The results of one run.
#[derive(Debug, Clone)]
pub struct RunResult {
    /// Every accepted macro point.
    pub table: Table,
    /// How it ended.
    pub outcome: Outcome,
}

/// Build and run a system, keeping every accepted point in memory.
///
/// A study explores settings, stable and not, and judges each run itself
/// (its error against the reference, divergence, growth): a constraint
/// broken beyond `[coupling] residual_limit` is part of what it shows, so
/// the limit is off in its runs (docs/studies.md).
pub fn run(spec: &SystemSpec, label: &str) -> RunResult {
    let mut spec = spec.clone();
    spec.coupling.residual_limit = ResidualLimit(None);
    let mut rec = MemoryRecorder::default();
    let outcome = match Simulation::new(&spec) {
        Err(e) => classify(e),
        Ok(mut sim) => match sim.run(&mut [&mut rec], &mut |_, _| {}) {
            Ok(_) => Outcome::Completed,
            Err(e) => classify(e),
        },
    };
    RunResult {
        table: Table::from_recorder(label, &rec),
        outcome,
    }
}

fn classify(e: MasterError) -> Outcome {
    match e {
        MasterError::Diverged { .. } => Outcome::Diverged(e.to_string()),
        other => Outcome::Failed(other.to_string()),
    }
}

/// Build a system without running it: the checks `tether run` makes before
/// the first step (names, capabilities, start values, initial multipliers).
pub fn check(spec: &SystemSpec) -> Result<(), MasterError> {
    Simulation::new(spec).map(drop)
}
